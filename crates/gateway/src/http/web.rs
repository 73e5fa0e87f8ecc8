//! The web page at `/`: one HTML file, a style sheet and a script, compiled into the
//! binary. Nothing is fetched from elsewhere at run time (plants are offline): no CDN, no
//! web fonts. The page follows `/api/events/stream` and draws its own plots.

use axum::Router;
use axum::http::header;
use axum::response::IntoResponse;
use axum::routing::get;

use super::AppState;

/// The page.
pub const INDEX_HTML: &str = include_str!("web/index.html");
/// Its style sheet.
pub const APP_CSS: &str = include_str!("web/app.css");
/// Its script.
pub const APP_JS: &str = include_str!("web/app.js");

/// The page's routes: method and path.
pub const PAGE_ROUTES: &[(&str, &str)] = &[("GET", "/"), ("GET", "/app.css"), ("GET", "/app.js")];

/// Routes serving the page.
pub(super) fn routes() -> Router<AppState> {
    Router::new()
        .route("/", get(|| asset("text/html; charset=utf-8", INDEX_HTML)))
        .route(
            "/app.css",
            get(|| asset("text/css; charset=utf-8", APP_CSS)),
        )
        .route(
            "/app.js",
            get(|| asset("text/javascript; charset=utf-8", APP_JS)),
        )
}

async fn asset(content_type: &'static str, body: &'static str) -> impl IntoResponse {
    (
        [
            (header::CONTENT_TYPE, content_type),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
}
