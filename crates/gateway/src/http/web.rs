//! The web page at `/`: one HTML file, a style sheet and four scripts, with the chart library
//! of its trend view (uPlot 1.6.32, MIT, vendored unchanged under `web/vendor/` with its
//! licence), all compiled into the binary. Nothing is fetched from elsewhere at run time
//! (plants are offline): no CDN, no web fonts. The page follows `/api/events/stream`,
//! draws its own small plots, asks `/api/history` for the trend view, `/api/states` and
//! `/api/production` for the production view, and `/api/alarms` and `/api/alarms/journal`
//! for the alarm view and the header's alarm banner.

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
/// The trend view's script.
pub const TREND_JS: &str = include_str!("web/trend.js");
/// The production view's script.
pub const PRODUCTION_JS: &str = include_str!("web/production.js");
/// The alarm view's script (and the header's alarm banner).
pub const ALARMS_JS: &str = include_str!("web/alarms.js");
/// uPlot, the trend view's charts (its release's minified script, unchanged).
pub const UPLOT_JS: &str = include_str!("web/vendor/uPlot.iife.min.js");
/// uPlot's style sheet.
pub const UPLOT_CSS: &str = include_str!("web/vendor/uPlot.min.css");
/// uPlot's licence (MIT), served beside it.
pub const UPLOT_LICENSE: &str = include_str!("web/vendor/uPlot.LICENSE");

/// The page's routes: method and path.
pub const PAGE_ROUTES: &[(&str, &str)] = &[
    ("GET", "/"),
    ("GET", "/app.css"),
    ("GET", "/app.js"),
    ("GET", "/trend.js"),
    ("GET", "/production.js"),
    ("GET", "/alarms.js"),
    ("GET", "/vendor/uPlot.iife.min.js"),
    ("GET", "/vendor/uPlot.min.css"),
    ("GET", "/vendor/uPlot.LICENSE"),
];

/// Routes serving the page.
pub(super) fn routes() -> Router<AppState> {
    const JS: &str = "text/javascript; charset=utf-8";
    const CSS: &str = "text/css; charset=utf-8";
    Router::new()
        .route("/", get(|| asset("text/html; charset=utf-8", INDEX_HTML)))
        .route("/app.css", get(|| asset(CSS, APP_CSS)))
        .route("/app.js", get(|| asset(JS, APP_JS)))
        .route("/trend.js", get(|| asset(JS, TREND_JS)))
        .route("/production.js", get(|| asset(JS, PRODUCTION_JS)))
        .route("/alarms.js", get(|| asset(JS, ALARMS_JS)))
        .route("/vendor/uPlot.iife.min.js", get(|| asset(JS, UPLOT_JS)))
        .route("/vendor/uPlot.min.css", get(|| asset(CSS, UPLOT_CSS)))
        .route(
            "/vendor/uPlot.LICENSE",
            get(|| asset("text/plain; charset=utf-8", UPLOT_LICENSE)),
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
