//! `b_spline` (docs/clip-format.md §2.5) over the wire: a JSON clip uploaded and posed over
//! REST, the same clip over gRPC with the protobuf enum, a BVH imported with
//! `?interpolation=b_spline`, and the OpenAPI document naming the mode.
//! Expected poses are closed forms of the lecture's B-spline worked by hand.

use formats::wire::proto::pb;
use serde_json::{Value, json};

use super::TestApp;
use crate::common::testdata_path;

/// A root translation with the default `reflect` ends and an arm rotation
/// about Z with `zero_slope` ends; angles 0, 0.8 and 0.2 rad.
fn clip() -> Value {
    let about_z = |a: f64| [0.0, 0.0, (a / 2.0).sin(), (a / 2.0).cos()];
    json!({"name": "smooth", "tracks": [
        {"joint": "root", "channel": "translation", "interpolation": "b_spline",
         "times": [0, 1, 2, 3], "values": [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]},
        {"joint": "arm", "channel": "rotation", "interpolation": "b_spline", "ends": "zero_slope",
         "times": [0, 1, 2], "values": [about_z(0.0), about_z(0.8), about_z(0.2)]},
    ]})
}

/// The hand-worked pose at `t` (0 or 1): the root at `(c_{i−1} + 4c_i + c_{i+1})/6`
/// with reflect's `c_{−1} = 2c_0 − c_1` (so exactly `c_0` at 0); the arm's
/// angle likewise with zero-slope's `c_{−1} = c_1` — one axis, so the
/// slerp construction moves the angle as the vector B-spline would.
fn expected(t: u32) -> ([f64; 3], [f64; 4]) {
    let (translation, angle) = match t {
        0 => ([0.0, 0.0, 0.0], (0.8 + 4.0 * 0.0 + 0.8) / 6.0),
        1 => ([5.0 / 6.0, 1.0 / 6.0, 0.0], (0.0 + 4.0 * 0.8 + 0.2) / 6.0),
        _ => unreachable!(),
    };
    let a: f64 = angle / 2.0;
    (translation, [0.0, 0.0, a.sin(), a.cos()])
}

fn close(got: &[f64], want: &[f64], what: &str) {
    assert_eq!(got.len(), want.len(), "{what}");
    let worst = got.iter().zip(want).map(|(g, w)| (g - w).abs()).fold(0.0, f64::max);
    assert!(worst <= 1e-6, "{what}: {got:?} vs {want:?}");
}

fn numbers(v: &Value) -> Vec<f64> {
    v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
}

#[tokio::test]
async fn a_b_spline_clip_is_stored_and_posed_over_rest_and_grpc() {
    let app = TestApp::start().await;
    let id = app.create_id(&clip().to_string(), None).await;
    let doc = app.get_json(&format!("/v1/clips/{id}")).await;
    assert_eq!(doc["tracks"][0]["interpolation"], "b_spline");
    assert_eq!(
        (&doc["tracks"][1]["interpolation"], &doc["tracks"][1]["ends"]),
        (&json!("b_spline"), &json!("zero_slope"))
    );

    for t in [0, 1] {
        let pose = app.get_json(&format!("/v1/clips/{id}/pose?t={t}")).await;
        let (translation, rotation) = expected(t);
        let joints = pose["joints"].as_array().unwrap();
        assert_eq!((&joints[0]["name"], &joints[1]["name"]), (&json!("root"), &json!("arm")));
        close(&numbers(&joints[0]["translation"]), &translation, &format!("REST root at {t}"));
        close(&numbers(&joints[1]["rotation"]), &rotation, &format!("REST arm at {t}"));
    }

    // gRPC: the stored clip carries the enum; a clip put with it poses alike.
    let mut grpc = app.grpc().await;
    let record = grpc.get_clip(pb::GetClipRequest { clip_id: id.clone() }).await.unwrap().into_inner();
    let tracks = record.clip.unwrap().tracks;
    assert!(tracks.iter().all(|t| t.interpolation == pb::Interpolation::BSpline as i32));
    assert_eq!(pb::Interpolation::BSpline as i32, 5, "the wire number is part of the contract");
    assert_eq!(pb::Interpolation::BSpline.as_str_name(), "INTERPOLATION_B_SPLINE");
    let (_, spec) = formats::wire::json::parse_clip(clip().to_string().as_bytes()).unwrap();
    // The import above named it `smooth`: a new version of that clip.
    let put =
        pb::PutClipRequest { clip: Some(formats::wire::proto::clip_to_pb(&spec)), replace: true, ..Default::default() };
    assert!(put.clip.as_ref().unwrap().tracks.iter().all(|t| t.interpolation == pb::Interpolation::BSpline as i32));
    let created = grpc.put_clip(put).await.unwrap().into_inner();
    for t in [0, 1] {
        let pose = grpc
            .sample(pb::SampleRequest { clip_id: created.id.clone(), time: t as f64, ..Default::default() })
            .await
            .unwrap()
            .into_inner();
        let (translation, rotation) = expected(t);
        let f = |v: &[f32]| v.iter().map(|&x| x as f64).collect::<Vec<_>>();
        close(&f(&pose.translations[..3]), &translation, &format!("gRPC root at {t}"));
        close(&f(&pose.rotations[4..]), &rotation, &format!("gRPC arm at {t}"));
    }
    // `tension` belongs to Catmull-Rom alone.
    let mut tense = clip();
    tense["tracks"][0]["tension"] = json!(0.5);
    let resp = app
        .http
        .post(app.url("/v1/clips"))
        .header("content-type", "application/json")
        .body(tense.to_string())
        .send()
        .await
        .unwrap();
    assert_eq!(resp.status(), 422);
    let problem: Value = resp.json().await.unwrap();
    assert_eq!((&problem["code"], &problem["pointer"]), (&json!("only_catmull_rom"), &json!("/tracks/0/tension")));
    app.stop().await;
}

#[tokio::test]
async fn bvh_import_takes_b_spline_and_the_openapi_document_names_it() {
    let app = TestApp::start().await;
    let path = testdata_path("bvh/131_03.bvh");
    let bvh = std::fs::read(&path).unwrap();
    let url = app.url("/v1/clips/import?format=bvh&interpolation=b_spline&name=smooth");
    let resp = app.http.post(url).body(bvh.clone()).send().await.unwrap();
    assert_eq!(resp.status(), 201);
    let body: Value = resp.json().await.unwrap();
    let id = body["clips"][0]["id"].as_str().unwrap();
    let doc = app.get_json(&format!("/v1/clips/{id}")).await;
    assert!(doc["tracks"].as_array().unwrap().iter().all(|t| t["interpolation"] == "b_spline"));

    let url = app.url("/v1/clips/import?format=bvh&interpolation=cubic_hermite");
    let resp = app.http.post(url).body(bvh).send().await.unwrap();
    assert_eq!(resp.status(), 400);
    let problem: Value = resp.json().await.unwrap();
    assert_eq!(problem["code"], "bad_interpolation");
    assert!(problem["detail"].as_str().unwrap().contains("b_spline"), "{problem}");

    let openapi = app.get_json("/openapi.json").await;
    let modes = openapi["components"]["schemas"]["InterpolationDoc"]["enum"].as_array().unwrap();
    assert!(modes.contains(&json!("b_spline")), "{modes:?}");
    let params = openapi["paths"]["/v1/clips/import"]["post"]["parameters"].as_array().unwrap();
    let interpolation = params.iter().find(|p| p["name"] == "interpolation").unwrap();
    assert!(interpolation["schema"]["pattern"].as_str().unwrap().contains("b_spline"), "{interpolation}");
    app.stop().await;
}
