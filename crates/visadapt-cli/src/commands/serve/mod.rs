//! `visadapt serve`: an interactive viewer in the browser. A local HTTP server (axum on a
//! small tokio runtime) holds the decoded image and serves one page (plain HTML, CSS and
//! JavaScript compiled into the binary, no external requests) and a JSON/PNG API whose
//! every frame, report and pixel comes from the library.

mod api;
mod viewer;

use crate::cli::ServeArgs;
use anyhow::Context;
use std::sync::{Arc, Mutex};

pub fn run(args: ServeArgs) -> anyhow::Result<()> {
    // The page switches glare and local adaptation on and off; the flags set how it
    // starts and the observer's options (age, pigmentation, radius) for both.
    let glare = visadapt::glare::Glare {
        age_years: args.viewing.glare.age,
        pigmentation: args.viewing.glare.pigmentation,
    };
    glare.validate()?;
    let local = visadapt::local::LocalAdaptation {
        radius_deg: args.viewing.adaptation.adaptation_radius,
        ..Default::default()
    };
    local.validate()?;
    let conditions = args.viewing.conditions(
        Some(&args.display),
        None,
        Some(&args.view),
        Some(&args.colour),
    );
    conditions.validate()?;

    let (image, scale) = args.units.read(
        &args.input,
        &args.limits.limits(),
        conditions.hot_pixel_fraction,
    )?;
    let (width, height) = (image.width, image.height);
    let defaults = viewer::Defaults {
        display_max_cd_m2: conditions.display_max_cd_m2,
        view: args.view.view(width, height),
        acuity: conditions.acuity,
        glare: conditions.glare.is_some(),
        local: matches!(
            conditions.adaptation,
            visadapt::operator::AdaptationMode::Local(_)
        ),
    };
    let viewer = viewer::Viewer::new(
        args.input.clone(),
        image,
        scale,
        conditions,
        defaults,
        glare,
        local,
    );

    // Two workers are plenty for one user's page; the model's own parallelism is rayon's.
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("cannot start the server's runtime")?;
    runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind((args.host.as_str(), args.port))
            .await
            .with_context(|| format!("cannot listen on {}:{}", args.host, args.port))?;
        let address = listener.local_addr()?;
        let app = api::router(Arc::new(Mutex::new(viewer)), address.ip().is_loopback());
        if !address.ip().is_loopback() {
            log::warn!("listening on {address}: other machines can reach the viewer and the image");
        }
        let url = format!("http://{address}/");
        println!(
            "visadapt: serving {} ({width}x{height}) at {url} (Ctrl-C to stop)",
            args.input.display()
        );
        if !args.no_open {
            let url = url.clone();
            std::thread::spawn(move || {
                if let Err(e) = webbrowser::open(&url) {
                    log::warn!("cannot open a browser ({e}); open {url} yourself");
                }
            });
        }
        axum::serve(listener, app)
            .with_graceful_shutdown(stop_signal())
            .await
            .context("the server failed")?;
        println!("visadapt: stopped");
        anyhow::Ok(())
    })
}

/// Ctrl-C (SIGINT), or SIGTERM on Unix.
async fn stop_signal() {
    let interrupt = async {
        if tokio::signal::ctrl_c().await.is_err() {
            std::future::pending::<()>().await;
        }
    };
    #[cfg(unix)]
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let terminate = std::future::pending::<()>();
    tokio::select! {
        _ = interrupt => {}
        _ = terminate => {}
    }
}
