//! The live page: `twin watch --serve` and `twin serve`. An HTTP server (axum) on a thread
//! and a single-threaded tokio runtime of its own; the watch's stepping loop stays
//! synchronous and only ever publishes into the [`hub::Hub`], which never waits on a browser.
//!
//! - [`hub`]: events, the bounded history, one bounded queue per browser.
//! - [`live`]: the watcher's observer (decimation, points, alerts, state).
//! - [`http`]: the routes; the page's assets are built into the binary (`assets/`).
//! - [`finished`]: the same events made from a finished watch, a record with a twin, a fleet.

pub mod finished;
pub mod http;
pub mod hub;
pub mod live;

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::Arc;
use std::thread::JoinHandle;

use axum::serve::ListenerExt;
use hub::Hub;

#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    #[error("cannot serve on {addr}: {source}")]
    Bind {
        addr: SocketAddr,
        #[source]
        source: std::io::Error,
    },
    #[error(
        "{flag} {addr}: not a loopback address; the page would be reachable from other \
         machines (add {allow} to allow it)"
    )]
    NotLoopback {
        addr: SocketAddr,
        flag: &'static str,
        allow: &'static str,
    },
    #[error("the page's server: {0}")]
    Runtime(std::io::Error),
}

/// A running server: its address; stopped when dropped.
pub struct Server {
    pub addr: SocketAddr,
    shutdown: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl Server {
    /// The page's URL.
    pub fn url(&self) -> String {
        format!("http://{}/", self.addr)
    }

    /// Whether the server's thread still runs (it ends only on a failure, or when stopped).
    pub fn running(&self) -> bool {
        self.thread.as_ref().is_some_and(|t| !t.is_finished())
    }

    pub fn stop(mut self) {
        self.stop_now();
    }

    fn stop_now(&mut self) {
        if let Some(s) = self.shutdown.take() {
            let _ = s.send(());
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.stop_now();
    }
}

/// Check that `addr` (given as `flag`) is loopback unless `public` (the flag `allow`).
pub fn check_bind(
    addr: SocketAddr,
    public: bool,
    flag: &'static str,
    allow: &'static str,
) -> Result<(), ServeError> {
    if addr.ip().is_loopback() || public {
        Ok(())
    } else {
        Err(ServeError::NotLoopback { addr, flag, allow })
    }
}

/// Bind `addr` (port 0: a free one) here, so a port in use is an error before any work, and
/// serve `hub` (and `views`, a fleet's structures) on a thread of its own.
pub fn start(
    addr: SocketAddr,
    hub: Arc<Hub>,
    views: BTreeMap<String, Arc<Hub>>,
    actions: http::Actions,
) -> Result<Server, ServeError> {
    let listener =
        std::net::TcpListener::bind(addr).map_err(|source| ServeError::Bind { addr, source })?;
    let local = listener
        .local_addr()
        .map_err(|source| ServeError::Bind { addr, source })?;
    listener
        .set_nonblocking(true)
        .map_err(ServeError::Runtime)?;
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_io()
        .enable_time()
        .build()
        .map_err(ServeError::Runtime)?;
    let (shutdown, stopped) = tokio::sync::oneshot::channel::<()>();
    let app = Arc::new(http::App::new(hub, views, actions));
    let thread = std::thread::Builder::new()
        .name("page".into())
        .spawn(move || {
            let served = runtime.block_on(async move {
                // Each event goes out as it is written (no Nagle delay for a small event).
                let listener = tokio::net::TcpListener::from_std(listener)?.tap_io(|tcp| {
                    let _ = tcp.set_nodelay(true);
                });
                // Stopped without waiting for the open event streams (they never end).
                tokio::select! {
                    served = axum::serve(listener, http::router(app)) => served,
                    _ = stopped => Ok(()),
                }
            });
            if let Err(e) = served {
                crate::notice::notify(crate::notice::Topic::LivePage, || {
                    format!("the page's server stopped: {e}; the watch goes on")
                });
            }
            runtime.shutdown_background();
        })
        .map_err(ServeError::Runtime)?;
    Ok(Server {
        addr: local,
        shutdown: Some(shutdown),
        thread: Some(thread),
    })
}
