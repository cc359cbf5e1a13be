//! Every route of the service, declared once: its REST method and path, the
//! scope its token needs, its class, its handler and its gRPC twin (or a
//! gRPC call alone). The router, the OpenAPI paths, the write rate limit,
//! shedding and frame compression, and the auth-matrix tests all read
//! [`ROUTES`], so a new route is one line here plus its handler (the
//! reference: `docs/api.md`).

use std::collections::HashMap;
use std::str::Split;
use std::sync::LazyLock;

use axum::Router;
use axum::extract::DefaultBodyLimit;
use axum::http::Method;
use axum::routing::MethodRouter;

use crate::auth::Scope;
use crate::rest::{
    broadcasts, characters, clips, graphs, health, import, mesh, motions, patch, poses, skeleton, stream, viewer,
};
use crate::state::AppState;

/// What a route does, as the limits see it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Class {
    /// Answers without changing state (a read sent as POST included).
    Read,
    /// Changes state: counted by the write rate limit.
    Write,
    /// A write whose body is spooled to disk under `max_import_bytes`.
    Import,
    /// Frames at a fixed rate: over gRPC, uncompressed and holding no
    /// in-flight slot once started (the stream caps govern them).
    FrameStream,
    /// Poses sent as a stream of messages (gRPC `SampleStream`): a read
    /// that holds its in-flight slot until its last message, uncompressed
    /// (a message is up to a megabyte).
    PoseStream,
    /// Probes and metrics: never shed, so an overloaded server looks alive.
    Operations,
    /// The viewer page, served with its files by `rest::viewer::router`.
    Page,
}

impl Class {
    /// Whether the write rate limit counts it.
    pub fn changes_state(self) -> bool {
        matches!(self, Class::Write | Class::Import)
    }
}

/// One route: REST, gRPC or both.
#[derive(Debug, Clone, Copy)]
pub struct Route {
    /// The REST method (lower case, as OpenAPI spells it) and path, if any.
    pub rest: Option<(&'static str, &'static str)>,
    /// The `inbetween.v1.Animation` method, if any.
    pub rpc: Option<&'static str>,
    /// The scope a token needs; `None`: open to anyone.
    pub scope: Option<Scope>,
    pub class: Class,
}

/// Whether the REST path template (`{id}` for one segment) matches `path`:
/// the rule [`PathTree`] implements, kept as the tests' reference.
#[cfg(test)]
fn template_matches(template: &str, path: &str) -> bool {
    let (mut want, mut got) = (template.split('/'), path.split('/'));
    loop {
        match (want.next(), got.next()) {
            (None, None) => return true,
            (Some(w), Some(g)) if w.starts_with('{') => {
                if g.is_empty() {
                    return false;
                }
            }
            (Some(w), Some(g)) if w == g => {}
            _ => return false,
        }
    }
}

/// The `Scope` a table row names (`Open`: none).
macro_rules! scope {
    (Open) => {
        None
    };
    ($scope:ident) => {
        Some(Scope::$scope)
    };
}

/// The table: REST routes (method, path, handler, scope, class, gRPC twin
/// or `-`), then gRPC calls without a REST twin. Emits [`ROUTES`],
/// [`mount`] and `RoutePaths` (the handlers' OpenAPI operations). Rows
/// of one path keep the order of its `Allow` header.
macro_rules! routes {
    (
        rest { $( ($method:ident, $path:literal, $module:ident :: $handler:ident, $scope:ident, $class:ident, $rpc:tt) ),* $(,)? }
        grpc { $( ($only_rpc:literal, $only_scope:ident, $only_class:ident) ),* $(,)? }
    ) => {
        /// Every route, REST rows first.
        pub const ROUTES: &[Route] = &[
            $( Route {
                rest: Some((stringify!($method), $path)),
                rpc: routes!(@rpc $rpc),
                scope: scope!($scope),
                class: Class::$class,
            }, )*
            $( Route { rest: None, rpc: Some($only_rpc), scope: scope!($only_scope), class: Class::$only_class }, )*
        ];

        /// `api` with every REST route but the page added.
        pub fn mount(api: Router<AppState>) -> Router<AppState> {
            $( let api = add(api, $path, Class::$class, axum::routing::$method($module::$handler)); )*
            api
        }

        /// The OpenAPI operations of the REST routes, merged into `rest::openapi::ApiDoc`.
        #[derive(utoipa::OpenApi)]
        #[openapi(paths($( $module::$handler ),*))]
        pub struct RoutePaths;
    };
    (@rpc -) => { None };
    (@rpc $rpc:literal) => { Some($rpc) };
}

routes! {
    rest {
        (post, "/v1/clips", clips::create_clip, Write, Write, -),
        (get, "/v1/clips", clips::list_clips, Read, Read, "ListClips"),
        (post, "/v1/clips/import", import::import_clips, Write, Import, -),
        (get, "/v1/clips/{id}", clips::get_clip, Read, Read, "GetClip"),
        (put, "/v1/clips/{id}", clips::replace_clip, Write, Write, "PutClip"),
        (patch, "/v1/clips/{id}", patch::patch_clip, Write, Write, -),
        (delete, "/v1/clips/{id}", clips::delete_clip, Write, Write, "DeleteClip"),
        (get, "/v1/clips/{id}/skeleton", skeleton::get_skeleton, Read, Read, "GetSkeleton"),
        (get, "/v1/clips/{id}/mesh", mesh::get_mesh, Read, Read, "GetMesh"),
        (get, "/v1/clips/{id}/pose", poses::get_pose, Read, Read, "Sample"),
        (post, "/v1/clips/{id}/sample", poses::sample, Read, Read, "SampleBatch"),
        (get, "/v1/clips/{id}/stream", stream::stream, Read, FrameStream, "StreamFrames"),
        (get, "/v1/stream", stream::motion_stream, Read, FrameStream, -),
        (post, "/v1/characters", characters::create_character, Write, Write, "CreateCharacter"),
        (get, "/v1/characters", characters::list_characters, Read, Read, "ListCharacters"),
        (post, "/v1/characters/import", import::import_characters, Write, Import, "ImportCharacter"),
        (get, "/v1/characters/{id}", characters::get_character, Read, Read, "GetCharacter"),
        (put, "/v1/characters/{id}", characters::replace_character, Write, Write, "ReplaceCharacter"),
        (delete, "/v1/characters/{id}", characters::delete_character, Write, Write, "DeleteCharacter"),
        (get, "/v1/characters/{id}/mesh", mesh::get_character_mesh, Read, Read, -),
        (post, "/v1/graphs", graphs::create_graph, Write, Write, "CreateGraph"),
        (get, "/v1/graphs", graphs::list_graphs, Read, Read, "ListGraphs"),
        (get, "/v1/graphs/{id}", graphs::get_graph, Read, Read, "GetGraph"),
        (put, "/v1/graphs/{id}", graphs::replace_graph, Write, Write, "ReplaceGraph"),
        (delete, "/v1/graphs/{id}", graphs::delete_graph, Write, Write, "DeleteGraph"),
        (post, "/v1/broadcasts", broadcasts::create, Write, Write, -),
        (get, "/v1/broadcasts", broadcasts::list, Read, Read, -),
        (get, "/v1/broadcasts/{id}", broadcasts::get, Read, Read, -),
        (delete, "/v1/broadcasts/{id}", broadcasts::delete, Write, Write, -),
        (post, "/v1/broadcasts/{id}/controls", broadcasts::control, Write, Write, -),
        (get, "/v1/broadcasts/{id}/stream", broadcasts::watch, Read, FrameStream, -),
        (post, "/v1/poses", motions::pose, Read, Read, "SampleMotion"),
        (post, "/v1/samples", motions::samples, Read, Read, "SampleMotionBatch"),
        (get, "/healthz", health::healthz, Open, Operations, -),
        (get, "/readyz", health::readyz, Open, Operations, -),
        (get, "/metrics", health::metrics, Admin, Operations, -),
        (get, "/viewer", viewer::viewer_page, Open, Page, -),
    }
    grpc {
        ("SampleStream", Read, PoseStream),
        ("Play", Read, FrameStream),
        ("Watch", Read, FrameStream),
        ("Ping", Open, Read),
    }
}

/// `api` with one REST route added.
fn add(api: Router<AppState>, path: &str, class: Class, route: MethodRouter<AppState>) -> Router<AppState> {
    match class {
        // The page is served with its files by `rest::viewer::router`, outside the strict query check.
        Class::Page => api,
        // Its body is spooled under max_import_bytes by the guard: no in-memory limit applies.
        Class::Import => api.route(path, route.layer(DefaultBodyLimit::disable())),
        _ => api.route(path, route),
    }
}

/// The REST routes by path segment, built once from [`ROUTES`]: a request's
/// class is found in one walk of its path, not a scan of the table with
/// string matching.
#[derive(Debug, Default)]
struct PathTree {
    literal: HashMap<&'static str, PathTree>,
    /// The `{id}` segment: any one non-empty segment.
    param: Option<Box<PathTree>>,
    /// The routes whose template ends here.
    routes: Vec<&'static Route>,
}

impl PathTree {
    fn build() -> PathTree {
        let mut root = PathTree::default();
        for route in ROUTES {
            let Some((_, template)) = route.rest else { continue };
            let mut node = &mut root;
            for segment in template.split('/') {
                node = if segment.starts_with('{') {
                    node.param.get_or_insert_default()
                } else {
                    node.literal.entry(segment).or_default()
                };
            }
            node.routes.push(route);
        }
        root
    }

    /// The first route whose template matches `segments` and that `wanted` accepts.
    fn find(&self, mut segments: Split<'_, char>, wanted: &impl Fn(&Route) -> bool) -> Option<&'static Route> {
        let Some(segment) = segments.next() else { return self.routes.iter().copied().find(|r| wanted(r)) };
        let literal = self.literal.get(segment).and_then(|next| next.find(segments.clone(), wanted));
        let param = || self.param.as_ref().filter(|_| !segment.is_empty())?.find(segments, wanted);
        literal.or_else(param)
    }
}

/// The table as a [`PathTree`], built at the first request.
static PATHS: LazyLock<PathTree> = LazyLock::new(PathTree::build);

/// The gRPC methods' classes, built at the first call.
static RPCS: LazyLock<HashMap<&'static str, Class>> =
    LazyLock::new(|| ROUTES.iter().filter_map(|r| Some((r.rpc?, r.class))).collect());

/// The first REST route matching `path` that `wanted` accepts.
fn route_where(path: &str, wanted: impl Fn(&Route) -> bool) -> Option<&'static Route> {
    PATHS.find(path.split('/'), &wanted)
}

/// The REST route `method path` answers, if any.
fn rest_route(method: &Method, path: &str) -> Option<&'static Route> {
    route_where(path, |r| r.rest.is_some_and(|(m, _)| method.as_str().eq_ignore_ascii_case(m)))
}

/// The import routes' paths (their bodies are spooled).
pub fn import_paths() -> Vec<&'static str> {
    ROUTES.iter().filter(|r| r.class == Class::Import).filter_map(|r| r.rest).map(|(_, path)| path).collect()
}

/// Whether the write rate limit counts `method path`: its route's class, or
/// for a request no route takes (404, 405), its method, unless its path is
/// one of a read sent as POST.
pub fn is_write(method: &Method, path: &str) -> bool {
    if let Some(route) = rest_route(method, path) {
        return route.class.changes_state();
    }
    if matches!(*method, Method::GET | Method::HEAD | Method::OPTIONS) {
        return false;
    }
    route_where(path, |r| r.rest.is_some_and(|(m, _)| m == "post") && r.class == Class::Read).is_none()
}

/// Whether a REST request to `path` (any method) is never shed.
pub fn never_shed(path: &str) -> bool {
    route_where(path, |r| r.class == Class::Operations).is_some()
}

/// The class of the gRPC call to `path`, if it is one of ours.
fn rpc_class(path: &str) -> Option<Class> {
    RPCS.get(path.strip_prefix("/inbetween.v1.Animation/")?).copied()
}

/// Whether the gRPC request to `path` is a stream of frames.
pub fn is_frame_rpc(path: &str) -> bool {
    rpc_class(path) == Some(Class::FrameStream)
}

/// Whether the gRPC call to `path` answers one message, which tonic may
/// compress (`compression::GrpcAnswers`); health and reflection included.
pub fn is_unary_rpc(path: &str) -> bool {
    !matches!(rpc_class(path), Some(Class::FrameStream | Class::PoseStream))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_state_changing_routes_are_writes() {
        assert!(is_write(&Method::POST, "/v1/clips"));
        assert!(is_write(&Method::POST, "/v1/clips/import"));
        assert!(is_write(&Method::PUT, "/v1/clips/x"));
        assert!(is_write(&Method::DELETE, "/v1/clips/x"));
        assert!(!is_write(&Method::POST, "/v1/clips/x/sample"));
        assert!(!is_write(&Method::POST, "/v1/poses"));
        assert!(!is_write(&Method::POST, "/v1/samples"));
        assert!(is_write(&Method::POST, "/v1/broadcasts/x/controls"));
        assert!(!is_write(&Method::GET, "/v1/clips/x/pose"));
        // No route: by method, but a read sent as POST stays a read whatever the method.
        assert!(is_write(&Method::POST, "/v1/nothing"));
        assert!(!is_write(&Method::PUT, "/v1/poses"));
        assert!(!is_write(&Method::GET, "/v1/nothing"));
    }

    #[test]
    fn probes_are_never_shed_and_frames_are_streams() {
        assert!(never_shed("/healthz") && never_shed("/readyz") && never_shed("/metrics"));
        assert!(!never_shed("/v1/clips") && !never_shed("/healthz/x"));
        assert!(is_frame_rpc("/inbetween.v1.Animation/StreamFrames"));
        assert!(is_frame_rpc("/inbetween.v1.Animation/Play"));
        assert!(is_frame_rpc("/inbetween.v1.Animation/Watch"));
        assert!(!is_frame_rpc("/inbetween.v1.Animation/SampleStream"));
        assert!(is_unary_rpc("/inbetween.v1.Animation/Sample") && is_unary_rpc("/grpc.health.v1.Health/Check"));
        assert!(!is_unary_rpc("/inbetween.v1.Animation/SampleStream"));
        assert!(!is_unary_rpc("/inbetween.v1.Animation/Watch"));
        assert_eq!(import_paths(), ["/v1/clips/import", "/v1/characters/import"]);
    }

    /// The tree answers as a scan of the table with [`template_matches`] would.
    #[test]
    fn the_tree_finds_what_a_scan_of_the_table_finds() {
        let paths = [
            "/v1/clips",
            "/v1/clips/",
            "/v1/clips/import",
            "/v1/clips/x",
            "/v1/clips/x/pose",
            "/v1/clips/x/sample",
            "/v1/clips/x/y",
            "/v1/clips//pose",
            "/v1/broadcasts/b/controls",
            "/v1/poses",
            "/healthz",
            "/healthz/x",
            "/metrics",
            "/viewer",
            "/",
            "",
            "/v1/nothing",
        ];
        let methods = [Method::GET, Method::POST, Method::PUT, Method::PATCH, Method::DELETE, Method::HEAD];
        for path in paths {
            for method in &methods {
                let scanned = ROUTES.iter().find(|r| {
                    r.rest.is_some_and(|(m, t)| method.as_str().eq_ignore_ascii_case(m) && template_matches(t, path))
                });
                assert_eq!(rest_route(method, path).map(|r| r.rest), scanned.map(|r| r.rest), "{method} {path}");
            }
            let operations = ROUTES
                .iter()
                .any(|r| r.class == Class::Operations && r.rest.is_some_and(|(_, t)| template_matches(t, path)));
            assert_eq!(never_shed(path), operations, "{path}");
        }
    }

    #[test]
    fn templates_match_one_segment_per_parameter() {
        assert!(template_matches("/v1/clips/{id}", "/v1/clips/a%2Fb"));
        assert!(!template_matches("/v1/clips/{id}", "/v1/clips/"));
        assert!(!template_matches("/v1/clips/{id}", "/v1/clips/a/b"));
        assert!(!template_matches("/v1/clips", "/v1/clips/"));
    }

    /// The scope each handler's OpenAPI operation declares is the table's.
    #[test]
    fn the_documented_security_is_the_tables() {
        let doc = <crate::rest::openapi::ApiDoc as utoipa::OpenApi>::openapi();
        for route in ROUTES {
            let Some((method, path)) = route.rest else { continue };
            let item = &doc.paths.paths[path];
            let op = match method {
                "get" => &item.get,
                "post" => &item.post,
                "put" => &item.put,
                "patch" => &item.patch,
                "delete" => &item.delete,
                other => panic!("{other}"),
            };
            let secured = op.as_ref().unwrap().security.as_ref().is_some_and(|s| !s.is_empty());
            assert_eq!(secured, route.scope.is_some(), "{method} {path}");
        }
    }
}
