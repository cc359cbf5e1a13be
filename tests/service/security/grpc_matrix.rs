//! Every RPC of `inbetween.v1.Animation` (read from the embedded descriptor
//! set, so a new RPC without a matrix entry fails) × {none, invalid, read,
//! write, admin}: allowed calls succeed, the rest end UNAUTHENTICATED or
//! PERMISSION_DENIED, and no refused write changes the store.

use std::collections::BTreeSet;

use formats::wire::proto::{FILE_DESCRIPTOR_SET, pb};
use prost::Message;
use server::auth::Scope;
use server::routes::ROUTES;
use tonic::Code;

use super::{
    ADMIN, Need, Outcome, Role, TINY_BVH, TestApp, expected, fresh_wave, scoped_tokens, snapshot, wave_pb, with_token,
};

/// The RPCs of the route table (`server::routes`) and what each needs.
fn rpcs() -> Vec<(&'static str, Need)> {
    ROUTES.iter().filter_map(|r| r.rpc.map(|name| (name, Need::of(r.scope)))).collect()
}

fn service_methods() -> BTreeSet<String> {
    let set = prost_types::FileDescriptorSet::decode(FILE_DESCRIPTOR_SET).unwrap();
    let service = set
        .file
        .iter()
        .flat_map(|f| f.service.iter())
        .find(|s| s.name() == "Animation")
        .expect("the Animation service");
    service.method.iter().map(|m| m.name().to_owned()).collect()
}

fn stream_request(id: &str) -> pb::StreamRequest {
    pb::StreamRequest { clip_id: id.to_owned(), fps: 60, max_frames: 1, ..Default::default() }
}

/// Calls `rpc` as `role` on a fresh clip; `Ok` when the call (and, for
/// streams, its first frame) succeeded.
async fn call(app: &TestApp, rpc: &str, role: Role) -> Result<(), tonic::Status> {
    let id = app.create_id(&fresh_wave(), Some(ADMIN)).await;
    let mut grpc = app.grpc().await;
    let t = role.token();
    match rpc {
        "Sample" => grpc
            .sample(with_token(pb::SampleRequest { clip_id: id, time: 0.5, ..Default::default() }, t))
            .await
            .map(drop),
        "SampleBatch" => {
            let when = pb::sample_batch_request::When::Times(pb::Times { values: vec![0.0, 1.0] });
            let req = pb::SampleBatchRequest { clip_id: id, when: Some(when), ..Default::default() };
            grpc.sample_batch(with_token(req, t)).await.map(drop)
        }
        "SampleStream" => {
            let when = pb::sample_batch_request::When::Times(pb::Times { values: vec![0.0, 1.0] });
            let req = pb::SampleBatchRequest { clip_id: id, when: Some(when), ..Default::default() };
            let mut batches = grpc.sample_stream(with_token(req, t)).await?.into_inner();
            batches.message().await?.expect("a first batch");
            Ok(())
        }
        "SampleMotion" => {
            let motion =
                pb::Motion { layers: vec![pb::Layer { clip_id: id, ..Default::default() }], ..Default::default() };
            let req = pb::SampleMotionRequest { motion: Some(motion), time: 0.5, ..Default::default() };
            grpc.sample_motion(with_token(req, t)).await.map(drop)
        }
        "SampleMotionBatch" => {
            let motion =
                pb::Motion { layers: vec![pb::Layer { clip_id: id, ..Default::default() }], ..Default::default() };
            let when = pb::sample_motion_batch_request::When::Times(pb::Times { values: vec![0.0, 1.0] });
            let req = pb::SampleMotionBatchRequest { motion: Some(motion), when: Some(when), ..Default::default() };
            grpc.sample_motion_batch(with_token(req, t)).await.map(drop)
        }
        "StreamFrames" => {
            let mut frames = grpc.stream_frames(with_token(stream_request(&id), t)).await?.into_inner();
            frames.message().await?.expect("a first frame");
            Ok(())
        }
        "Play" => {
            let open = pb::PlaybackControl {
                op: Some(pb::playback_control::Op::Open(pb::Open { stream: Some(stream_request(&id)), paused: false })),
            };
            // The request stream stays open until the first frame has come.
            let (tx, rx) = tokio::sync::mpsc::channel(1);
            tx.send(open).await.unwrap();
            let inbound = tokio_stream::wrappers::ReceiverStream::new(rx);
            let mut frames = grpc.play(with_token(inbound, t)).await?.into_inner();
            frames.message().await?.expect("a first frame");
            drop(tx);
            Ok(())
        }
        "Watch" => {
            let created = app.http.post(app.url("/v1/broadcasts")).bearer_auth(ADMIN);
            let body = serde_json::json!({"motion": {"layers": [{"clip": id}]}, "fps": 60});
            let created: serde_json::Value = created.json(&body).send().await.unwrap().json().await.unwrap();
            let req =
                pb::WatchRequest { broadcast_id: created["id"].as_str().unwrap().to_owned(), ..Default::default() };
            let mut frames = grpc.watch(with_token(req, t)).await?.into_inner();
            frames.message().await?.expect("a first frame");
            Ok(())
        }
        "GetClip" => grpc.get_clip(with_token(pb::GetClipRequest { clip_id: id }, t)).await.map(drop),
        "ListClips" => grpc.list_clips(with_token(pb::ListClipsRequest::default(), t)).await.map(drop),
        "GetSkeleton" => grpc.get_skeleton(with_token(pb::GetClipRequest { clip_id: id }, t)).await.map(drop),
        // The clip is JSON, without a mesh: allowed is NOT_FOUND `no_mesh` (tests/service/api/mesh.rs: the Fox's).
        "GetMesh" => match grpc.get_mesh(with_token(pb::GetClipRequest { clip_id: id }, t)).await {
            Err(s) if s.metadata().get("x-error-code").is_some_and(|c| c == "no_mesh") => Ok(()),
            other => other.map(drop),
        },
        "PutClip" => {
            let clip = pb::Clip { name: format!("wave {}", server::store::new_clip_id()), ..wave_pb() };
            let req = pb::PutClipRequest { clip_id: id, clip: Some(clip), ..Default::default() };
            grpc.put_clip(with_token(req, t)).await.map(drop)
        }
        "DeleteClip" => grpc.delete_clip(with_token(pb::DeleteClipRequest { clip_id: id }, t)).await.map(drop),
        "Ping" => grpc.ping(with_token(pb::PingRequest::default(), t)).await.map(drop),
        "CreateCharacter" => {
            let req = pb::CreateCharacterRequest { character: Some(fresh_character()), replace: false };
            grpc.create_character(with_token(req, t)).await.map(drop)
        }
        "ListCharacters" => grpc.list_characters(with_token(pb::ListCharactersRequest::default(), t)).await.map(drop),
        "GetCharacter" => {
            let character_id = admin_character(&mut grpc).await;
            grpc.get_character(with_token(pb::GetCharacterRequest { character_id }, t)).await.map(drop)
        }
        "ReplaceCharacter" => {
            let character_id = admin_character(&mut grpc).await;
            let req =
                pb::ReplaceCharacterRequest { character_id, character: Some(fresh_character()), if_version: None };
            grpc.replace_character(with_token(req, t)).await.map(drop)
        }
        "DeleteCharacter" => {
            let character_id = admin_character(&mut grpc).await;
            let req = pb::DeleteCharacterRequest { character_id, if_version: None };
            grpc.delete_character(with_token(req, t)).await.map(drop)
        }
        "ImportCharacter" => {
            let name = server::store::new_clip_id();
            let req =
                pb::ImportCharacterRequest { data: TINY_BVH.into(), format: "bvh".into(), name, ..Default::default() };
            grpc.import_character(with_token(req, t)).await.map(drop)
        }
        "CreateGraph" => {
            let req = pb::CreateGraphRequest { document: fresh_graph(&id), replace: false };
            grpc.create_graph(with_token(req, t)).await.map(drop)
        }
        "ListGraphs" => grpc.list_graphs(with_token(pb::ListGraphsRequest::default(), t)).await.map(drop),
        "GetGraph" => {
            let graph_id = admin_graph(&mut grpc, &id).await;
            grpc.get_graph(with_token(pb::GetGraphRequest { graph_id }, t)).await.map(drop)
        }
        "ReplaceGraph" => {
            let graph_id = admin_graph(&mut grpc, &id).await;
            let req = pb::ReplaceGraphRequest { graph_id, document: fresh_graph(&id), if_version: None };
            grpc.replace_graph(with_token(req, t)).await.map(drop)
        }
        "DeleteGraph" => {
            let graph_id = admin_graph(&mut grpc, &id).await;
            let req = pb::DeleteGraphRequest { graph_id, if_version: None };
            grpc.delete_graph(with_token(req, t)).await.map(drop)
        }
        other => panic!("no call for {other}"),
    }
}

/// A one-joint character under a name no other has.
fn fresh_character() -> pb::Character {
    let joint = pb::Joint { name: "root".into(), ..Default::default() };
    let skeleton = pb::Skeleton { joints: vec![joint] };
    pb::Character { name: server::store::new_clip_id(), skeleton: Some(skeleton), ..Default::default() }
}

/// A one-node graph document over `clip` under a name no other has.
fn fresh_graph(clip: &str) -> String {
    serde_json::json!({"name": server::store::new_clip_id(), "nodes": {"a": {"clip": clip}}, "output": "a"}).to_string()
}

/// A fresh graph over `clip` made by the admin; its id.
async fn admin_graph(
    grpc: &mut pb::animation_client::AnimationClient<tonic::transport::Channel>,
    clip: &str,
) -> String {
    let req = pb::CreateGraphRequest { document: fresh_graph(clip), replace: false };
    grpc.create_graph(with_token(req, Some(ADMIN))).await.unwrap().into_inner().id
}

/// A fresh character made by the admin; its id.
async fn admin_character(grpc: &mut pb::animation_client::AnimationClient<tonic::transport::Channel>) -> String {
    let req = pb::CreateCharacterRequest { character: Some(fresh_character()), replace: false };
    grpc.create_character(with_token(req, Some(ADMIN))).await.unwrap().into_inner().id
}

#[tokio::test]
async fn every_rpc_checks_its_scope() {
    let rpcs = rpcs();
    let listed: BTreeSet<String> = rpcs.iter().map(|(name, _)| name.to_string()).collect();
    assert_eq!(service_methods(), listed, "every RPC needs a matrix entry, and only those");

    let app = TestApp::builder().configure(scoped_tokens).start().await;
    let mut refused_writes = 0;
    for &(rpc, need) in &rpcs {
        for role in Role::ALL {
            let before = snapshot(&app).await;
            let result = call(&app, rpc, role).await;
            let after = snapshot(&app).await;
            let what = format!("{rpc} as {role:?}");
            match expected(need, role) {
                Outcome::Allowed => assert!(result.is_ok(), "{what}: {result:?}"),
                refused => {
                    let status = result.expect_err(&what);
                    let (code, stable) = match refused {
                        Outcome::Unauthenticated => (Code::Unauthenticated, "unauthorized"),
                        _ => (Code::PermissionDenied, "insufficient_scope"),
                    };
                    assert_eq!(status.code(), code, "{what}: {status:?}");
                    assert_eq!(status.metadata().get("x-error-code").unwrap(), stable, "{what}");
                    let created: Vec<_> = after.iter().filter(|c| !before.contains(c)).collect();
                    assert!(created.len() <= 1, "{what} created a clip: {created:?}");
                    assert!(before.iter().all(|c| after.contains(c)), "{what} changed or deleted a clip");
                    if need == Need::Scope(Scope::Write) {
                        refused_writes += 1;
                    }
                }
            }
        }
    }
    let writes = rpcs.iter().filter(|(_, need)| *need == Need::Scope(Scope::Write)).count();
    assert_eq!(refused_writes, writes * 3);
    app.stop().await;
}
