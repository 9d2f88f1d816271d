//! The HTTP side: routes, query parameters and their one-line errors.
//!
//! `GET /` the page; `GET /api/frame?...` a PNG (its `x-visadapt-showing` header says
//! which adaptation and glare it shows); `GET /api/report?...` the JSON of `map --json`;
//! `GET /api/pixel?x=&y=&...` one pixel. Every parameter is checked here
//! (unknown, repeated, malformed or out of range: HTTP 400 with one line saying which and
//! why); the work runs on a blocking thread, one request at a time, against the shared
//! [`Viewer`].

use super::viewer::{Failure, Outcome, Params, Rendering, Viewer};
use axum::Router;
use axum::extract::{RawQuery, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use std::sync::{Arc, Mutex};

const PAGE: &str = include_str!("page/index.html");
const SCRIPT: &str = include_str!("page/viewer.js");
const STYLE: &str = include_str!("page/viewer.css");

/// Query parameters of a frame or report.
const FRAME_KEYS: [&str; 10] = [
    "peak",
    "t",
    "from",
    "display_max",
    "fov",
    "acuity",
    "width",
    "mode",
    "glare",
    "adaptation",
];
/// Extra parameters of `/api/pixel`.
const PIXEL_KEYS: [&str; 3] = ["x", "y", "change"];

/// The response header of `/api/frame` that says what the frame shows (adaptation, glare).
pub const SHOWING_HEADER: &str = "x-visadapt-showing";

/// The relative change `/api/pixel` asks about when `change` is not given: 10 %.
const DEFAULT_CHANGE: f64 = 0.1;

pub type Shared = Arc<Mutex<Viewer>>;

/// The routes. With `loopback_only` (the server listens on a loopback address), a request
/// whose `Host` is not a loopback name or address is refused (403): a web page elsewhere
/// cannot reach the viewer through a name that resolves to 127.0.0.1 (DNS rebinding).
pub fn router(viewer: Shared, loopback_only: bool) -> Router {
    let host_check = axum::middleware::from_fn(
        move |request: axum::extract::Request, next: axum::middleware::Next| async move {
            if loopback_only && !loopback_host(request.headers().get(header::HOST)) {
                return (
                    StatusCode::FORBIDDEN,
                    "the viewer answers loopback names only\n",
                )
                    .into_response();
            }
            next.run(request).await
        },
    );
    Router::new()
        .route(
            "/",
            get(|| async { page(PAGE, "text/html; charset=utf-8") }),
        )
        .route(
            "/viewer.js",
            get(|| async { page(SCRIPT, "text/javascript; charset=utf-8") }),
        )
        .route(
            "/viewer.css",
            get(|| async { page(STYLE, "text/css; charset=utf-8") }),
        )
        .route("/api/frame", get(frame))
        .route("/api/report", get(report))
        .route("/api/pixel", get(pixel))
        .fallback(|| async { (StatusCode::NOT_FOUND, "not found\n") })
        .layer(host_check)
        .with_state(viewer)
}

/// `Host` names this machine's loopback: `localhost`, `127.x.x.x` or `[::1]`, any port.
fn loopback_host(host: Option<&header::HeaderValue>) -> bool {
    let Some(host) = host.and_then(|h| h.to_str().ok()) else {
        return false;
    };
    let name = match host.strip_prefix('[') {
        Some(v6) => v6.split(']').next().unwrap_or(""),
        None => host.rsplit_once(':').map_or(host, |(name, _)| name),
    };
    name.eq_ignore_ascii_case("localhost")
        || name
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback())
}

fn page(body: &'static str, content_type: &'static str) -> Response {
    ([(header::CONTENT_TYPE, content_type)], body).into_response()
}

async fn frame(State(viewer): State<Shared>, RawQuery(query): RawQuery) -> Response {
    run(viewer, move |v| {
        let q = Query::parse(query.as_deref(), &FRAME_KEYS)?;
        let params = q.params(v)?;
        let png = v.frame_png(&params)?;
        // What the frame shows, for the page's status line (plain ASCII).
        let showing = header::HeaderValue::from_str(&v.showing(&params))
            .map_err(|e| Failure::Internal(format!("the status line: {e}")))?;
        Ok((
            [
                (
                    header::CONTENT_TYPE,
                    header::HeaderValue::from_static("image/png"),
                ),
                (header::HeaderName::from_static(SHOWING_HEADER), showing),
            ],
            png,
        )
            .into_response())
    })
    .await
}

async fn report(State(viewer): State<Shared>, RawQuery(query): RawQuery) -> Response {
    run(viewer, move |v| {
        let q = Query::parse(query.as_deref(), &FRAME_KEYS)?;
        let json = v.report(&q.params(v)?)?;
        Ok(json_response(&json))
    })
    .await
}

async fn pixel(State(viewer): State<Shared>, RawQuery(query): RawQuery) -> Response {
    run(viewer, move |v| {
        let keys: Vec<&str> = FRAME_KEYS.iter().chain(&PIXEL_KEYS).copied().collect();
        let q = Query::parse(query.as_deref(), &keys)?;
        let params = q.params(v)?;
        let x = q.required("x", |s| parse_index(s, "x"))?;
        let y = q.required("y", |s| parse_index(s, "y"))?;
        let change = q
            .get("change", |s| {
                parse_f64(s, "change").and_then(|c| {
                    if c.is_finite() && c.abs() <= 1e6 {
                        Ok(c)
                    } else {
                        Err(format!("invalid change {s}: must be a finite fraction"))
                    }
                })
            })?
            .unwrap_or(DEFAULT_CHANGE);
        let json = v.pixel(&params, x, y, change)?;
        Ok(json_response(&json))
    })
    .await
}

fn json_response(json: &serde_json::Value) -> Response {
    (
        [(header::CONTENT_TYPE, "application/json")],
        json.to_string(),
    )
        .into_response()
}

/// Run `work` on a blocking thread with the viewer locked; a failure becomes a one-line
/// text response (400 for the caller's fault, 500 for ours, a panic included).
async fn run(
    viewer: Shared,
    work: impl FnOnce(&mut Viewer) -> Outcome<Response> + Send + 'static,
) -> Response {
    let done = tokio::task::spawn_blocking(move || {
        let mut v = viewer.lock().unwrap_or_else(|poisoned| {
            // A request panicked while holding the viewer: its caches may be half-written.
            let mut v = poisoned.into_inner();
            v.clear_caches();
            viewer.clear_poison();
            v
        });
        work(&mut v)
    })
    .await;
    let failure = match done {
        Ok(Ok(response)) => return no_store(response),
        Ok(Err(f)) => f,
        Err(e) => Failure::Internal(format!("the request failed: {e}")),
    };
    let (status, message) = match failure {
        Failure::BadRequest(m) => (StatusCode::BAD_REQUEST, m),
        Failure::Internal(m) => (StatusCode::INTERNAL_SERVER_ERROR, m),
    };
    let line = message.replace(['\n', '\r'], " ");
    no_store((status, format!("{line}\n")).into_response())
}

fn no_store(mut r: Response) -> Response {
    r.headers_mut().insert(
        header::CACHE_CONTROL,
        header::HeaderValue::from_static("no-store"),
    );
    r
}

impl From<String> for Failure {
    fn from(message: String) -> Self {
        Failure::BadRequest(message)
    }
}

/// A parsed query string: each known key at most once.
struct Query(Vec<(String, String)>);

impl Query {
    fn parse(query: Option<&str>, known: &[&str]) -> Result<Query, Failure> {
        let mut pairs: Vec<(String, String)> = Vec::new();
        for (k, v) in form_urlencoded::parse(query.unwrap_or("").as_bytes()) {
            if !known.contains(&k.as_ref()) {
                return Err(Failure::BadRequest(format!(
                    "unknown parameter {k:?} (known: {})",
                    known.join(", ")
                )));
            }
            if pairs.iter().any(|(key, _)| *key == k) {
                return Err(Failure::BadRequest(format!("parameter {k:?} given twice")));
            }
            pairs.push((k.into_owned(), v.into_owned()));
        }
        Ok(Query(pairs))
    }

    fn get<T>(
        &self,
        key: &str,
        parse: impl Fn(&str) -> Result<T, String>,
    ) -> Result<Option<T>, Failure> {
        match self.0.iter().find(|(k, _)| k == key) {
            Some((_, v)) => Ok(Some(parse(v)?)),
            None => Ok(None),
        }
    }

    fn required<T>(&self, key: &str, parse: impl Fn(&str) -> Result<T, String>) -> Outcome<T> {
        self.get(key, parse)?
            .ok_or_else(|| Failure::BadRequest(format!("missing parameter {key:?}")))
    }

    /// The frame parameters, with the server's defaults for those not given.
    fn params(&self, v: &Viewer) -> Outcome<Params> {
        let luminance = |name: &'static str| {
            move |s: &str| positive(s, name, "must be a positive, finite luminance in cd/m²")
        };
        let peak = self.get("peak", luminance("peak"))?;
        let from = self.get("from", luminance("from"))?;
        let t = self.get("t", |s| {
            let t = parse_f64(s, "t")?;
            if t.is_finite() && t >= 0.0 {
                Ok(t)
            } else {
                Err(format!(
                    "invalid t {s}: must be a finite, non-negative number of seconds"
                ))
            }
        })?;
        let switch = match (from, t) {
            (Some(from), Some(t)) => Some((from, t)),
            (None, None) => None,
            (Some(_), None) => return Err("parameter \"from\" needs \"t\"".to_string().into()),
            (None, Some(_)) => return Err("parameter \"t\" needs \"from\"".to_string().into()),
        };
        let display_max = self
            .get("display_max", |s| {
                positive(
                    s,
                    "display_max",
                    "must be a positive, finite luminance in cd/m²",
                )
            })?
            .unwrap_or(v.defaults.display_max_cd_m2);
        let fov = self.get("fov", |s| {
            let f = parse_f64(s, "fov")?;
            if f.is_finite() && f > 0.0 && f < 180.0 {
                Ok(f)
            } else {
                Err(format!(
                    "invalid fov {s}: must be between 0 and 180 degrees (perspective)"
                ))
            }
        })?;
        let switch_of = |name: &'static str| {
            move |s: &str| match s {
                "1" | "true" => Ok(true),
                "0" | "false" => Ok(false),
                _ => Err(format!("invalid {name} {s:?}: must be 0 or 1")),
            }
        };
        let acuity = self
            .get("acuity", switch_of("acuity"))?
            .unwrap_or(v.defaults.acuity);
        let glare = self
            .get("glare", switch_of("glare"))?
            .unwrap_or(v.defaults.glare);
        let local = self
            .get("adaptation", |s| match s {
                "global" => Ok(false),
                "local" => Ok(true),
                _ => Err(format!("invalid adaptation {s:?}: must be global or local")),
            })?
            .unwrap_or(v.defaults.local);
        let width = self.get("width", |s| {
            let w: usize = s
                .parse()
                .map_err(|_| format!("invalid width {s:?}: not a whole number of pixels"))?;
            if (1..=v.width()).contains(&w) {
                Ok(w)
            } else {
                Err(format!(
                    "invalid width {w}: must be between 1 and the image width {}",
                    v.width()
                ))
            }
        })?;
        let rendering = self
            .get("mode", |s| match s {
                "model" => Ok(Rendering::Model),
                "exposure" => Ok(Rendering::Exposure),
                _ => Err(format!("invalid mode {s:?}: must be model or exposure")),
            })?
            .unwrap_or(Rendering::Model);
        Ok(Params {
            peak_cd_m2: peak,
            switch,
            display_max_cd_m2: display_max,
            fov_deg: fov,
            acuity,
            width,
            rendering,
            glare,
            local,
        })
    }
}

fn parse_f64(s: &str, name: &str) -> Result<f64, String> {
    s.trim()
        .parse::<f64>()
        .map_err(|_| format!("invalid {name} {s:?}: not a number"))
}

fn positive(s: &str, name: &str, reason: &str) -> Result<f64, String> {
    let v = parse_f64(s, name)?;
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(format!("invalid {name} {s}: {reason}"))
    }
}

fn parse_index(s: &str, name: &str) -> Result<usize, String> {
    s.parse()
        .map_err(|_| format!("invalid {name} {s:?}: not a pixel index (0, 1, 2, ...)"))
}
