//! The OpenAPI 3 document, generated from the handlers' `#[utoipa::path]`
//! annotations and the wire types' `ToSchema` derives, served at
//! `/openapi.json`, with Swagger UI at `/docs` (vendored into the binary:
//! the page needs no download at build or run time).

use utoipa::openapi::path::ParameterIn;
use utoipa::openapi::schema::{Schema, SchemaType, Type};
use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityScheme};
use utoipa::openapi::{Content, Ref, RefOr, Response, ResponseBuilder};
use utoipa::{Modify, OpenApi};
use utoipa_swagger_ui::SwaggerUi;

use super::schemas::{JointPoseSchema, PoseSchema, PosesSchema, Problem, Warning};
use crate::error::PROBLEM_JSON;
use crate::routes::RoutePaths;

/// The bearer scheme, and on every operation that takes it the two answers
/// a token can draw (401 missing/unknown, 403 lacking the scope), so no
/// handler has to list them and none can forget.
struct BearerAuth;

impl Modify for BearerAuth {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        let components = openapi.components.get_or_insert_with(Default::default);
        components.add_security_scheme(
            "bearer",
            SecurityScheme::Http(HttpBuilder::new().scheme(HttpAuthScheme::Bearer).build()),
        );
        for (path, item) in openapi.paths.paths.iter_mut() {
            let operations = [&mut item.get, &mut item.put, &mut item.post, &mut item.patch, &mut item.delete];
            for op in operations.into_iter().flatten() {
                let mut add = |status: &str, what: &str| {
                    op.responses.responses.entry(status.to_owned()).or_insert_with(|| problem_response(what));
                };
                // Query parameters (`rest::query`) and headers are parsed strictly on every
                // API and operations route; the viewer page is a static file.
                if path != "/viewer" {
                    add(
                        "400",
                        "A parameter or header that does not parse, or a query parameter the route does not list \
                         or gives twice (`unknown_parameter`, `repeated_parameter`)",
                    );
                }
                let json_body = matches!(&op.request_body, Some(RefOr::T(b))
                    if b.content.keys().any(|k| k == "application/json" || k.ends_with("+json")));
                if json_body {
                    add("413", "Request body over the size limit");
                    add("415", "The body is not declared application/json");
                }
                if op.security.as_ref().is_some_and(|s| !s.is_empty()) {
                    add("401", "Token missing or unknown (where the route's scope is enforced)");
                    add("403", "The token lacks the scope this route needs");
                }
                // A header is a string or absent, never JSON null (utoipa makes an optional one nullable).
                for p in op.parameters.iter_mut().flatten() {
                    if let RefOr::T(p) = p
                        && p.parameter_in == ParameterIn::Header
                        && let Some(RefOr::T(Schema::Object(o))) = p.schema.as_mut()
                    {
                        o.schema_type = SchemaType::Type(Type::String);
                    }
                }
                // Every error body is problem+json, whatever the annotation said.
                for (status, response) in op.responses.responses.iter_mut() {
                    if let (true, RefOr::T(r)) = (status.starts_with(['4', '5']), response)
                        && let Some(content) = r.content.shift_remove("application/json")
                    {
                        r.content.insert(PROBLEM_JSON.to_owned(), content);
                    }
                }
            }
        }
    }
}

/// The operations of the route table's REST routes (`routes`), before
/// [`BearerAuth`] completes them.
struct RouteOperations;

impl Modify for RouteOperations {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        openapi.merge(RoutePaths::openapi());
    }
}

fn problem_response(description: &str) -> RefOr<Response> {
    let content = Content::new(Some(RefOr::Ref(Ref::from_schema_name("Problem"))));
    RefOr::T(ResponseBuilder::new().description(description).content(PROBLEM_JSON, content).build())
}

#[derive(OpenApi)]
#[openapi(
    info(title = "inbetween", description = "Keyframe clips in, inbetweens out. Described in the repository's docs: the clip document and how every pose is evaluated, `docs/clip-format.md` (the pose: its §4); composed motions (layers, crossfades, root motion, joint subsets, streams), `docs/motion.md`; inverse kinematics, `docs/ik.md`; broadcasts, `docs/broadcasts.md`; imports, `docs/import.md`; warnings, `docs/warnings.md`; every route with curl, `docs/api.md`; every setting, `docs/configuration.md`."),
    components(schemas(Problem, Warning, PoseSchema, PosesSchema, JointPoseSchema, super::stream::StreamOpen)),
    modifiers(&RouteOperations, &BearerAuth),
    tags(
        (name = "clips", description = "Store and fetch keyframe clips (the document: `docs/clip-format.md`)"),
        (name = "poses", description = "Evaluate poses of a clip (`docs/clip-format.md`, the pose: its §4) or of a composed motion (`docs/motion.md`)"),
        (name = "streams", description = "Fixed-rate frames over a WebSocket (`docs/api.md`, \"Streams\"; motions: `docs/motion.md`, \"Streams\")"),
        (name = "characters", description = "Skeletons with humanoid roles, to play any take on (`docs/characters.md`)"),
        (name = "graphs", description = "Animation graphs: parameters, blend spaces and state machines, stored and versioned (`docs/graphs.md`)"),
        (name = "broadcasts", description = "One shared playback, many viewers (`docs/broadcasts.md`)"),
        (name = "operations", description = "Health and metrics"),
        (name = "viewer", description = "The browser viewer page"),
    )
)]
pub struct ApiDoc;

/// `/openapi.json` and `/docs`.
pub fn router<S: Clone + Send + Sync + 'static>() -> axum::Router<S> {
    SwaggerUi::new("/docs").url("/openapi.json", ApiDoc::openapi()).into()
}
