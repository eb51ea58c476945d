//! The hub between the watch and the page: events in from the watcher's thread without ever
//! waiting, a bounded recent history for a browser that connects or reconnects, and one bounded
//! queue per browser.
//!
//! The watcher publishes; the hub stamps each event with a sequence number, keeps it in the
//! history (points and the other events in rings of their own, so a long stream's points never
//! push the alerts out) and offers it to every client's queue with `try_send`. A client whose
//! queue is full (a slow or stalled browser) is dropped: its queue closes, the browser's
//! `EventSource` reconnects and gets the history again. Nothing here blocks the publisher but a
//! mutex held by the other side only to copy the history's `Arc`s.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

use serde_json::Value;
use tokio::sync::mpsc;

/// One published event: its sequence number and its JSON text (the object with `seq` in it).
#[derive(Debug)]
pub struct Published {
    pub seq: u64,
    pub text: String,
}

/// The history's and the queues' bounds.
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    /// Points kept (the page's plots on a reconnect).
    pub points: usize,
    /// Other events kept (alerts, state, diagnoses).
    pub events: usize,
    /// Events a client's queue holds before the client is dropped.
    pub queue: usize,
    /// Browsers served at once.
    pub clients: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            // 80 s of stream at the page's 50 points per second.
            points: 4000,
            events: 2000,
            queue: 8192,
            clients: 64,
        }
    }
}

/// What the hub did, for /api/stats and the benchmark.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct Stats {
    pub published: u64,
    /// Clients dropped because their queue was full.
    pub dropped_clients: u64,
    /// Events that found a client's queue full (the client was dropped then).
    pub dropped_events: u64,
    pub clients: usize,
}

struct Inner {
    seq: u64,
    /// The first event of every connection (channels, tolerance, mode).
    meta: Option<Arc<Published>>,
    points: VecDeque<Arc<Published>>,
    events: VecDeque<Arc<Published>>,
    /// The latest state event: kept apart so the history always has one.
    state: Option<Arc<Published>>,
    clients: Vec<mpsc::Sender<Arc<Published>>>,
    /// Alerts with a sequence number of the watch's, for /api/ack; and the diagnoses seen.
    alert_seqs: VecDeque<u64>,
    diagnoses: Vec<Value>,
}

pub struct Hub {
    inner: Mutex<Inner>,
    limits: Limits,
    published: AtomicU64,
    dropped_clients: AtomicU64,
    dropped_events: AtomicU64,
}

/// What a new client gets: the history (meta first), then its queue.
pub struct Subscription {
    pub history: Vec<Arc<Published>>,
    pub live: mpsc::Receiver<Arc<Published>>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Meta,
    Point,
    State,
    Other,
}

impl Hub {
    pub fn new(limits: Limits) -> Arc<Hub> {
        Arc::new(Hub {
            inner: Mutex::new(Inner {
                seq: 0,
                meta: None,
                points: VecDeque::new(),
                events: VecDeque::new(),
                state: None,
                clients: Vec::new(),
                alert_seqs: VecDeque::new(),
                diagnoses: Vec::new(),
            }),
            limits,
            published: AtomicU64::new(0),
            dropped_clients: AtomicU64::new(0),
            dropped_events: AtomicU64::new(0),
        })
    }

    pub fn limits(&self) -> Limits {
        self.limits
    }

    /// A poisoned lock (a panic elsewhere while it was held) still guards consistent data:
    /// every update below is a push or a pop.
    fn lock(&self) -> MutexGuard<'_, Inner> {
        self.inner
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Publish `event` (a JSON object; `type` names it for the page); it returns at once.
    pub fn publish(&self, kind: Kind, mut event: Value) {
        let mut inner = self.lock();
        inner.seq += 1;
        let seq = inner.seq;
        if let Value::Object(map) = &mut event {
            map.insert("seq".into(), Value::from(seq));
        }
        if event.get("type").and_then(Value::as_str) == Some("alert") {
            if let Some(alert) = event.get("alert") {
                if let Some(s) = alert.get("seq").and_then(Value::as_u64) {
                    inner.alert_seqs.push_back(s);
                    if inner.alert_seqs.len() > self.limits.events {
                        inner.alert_seqs.pop_front();
                    }
                }
                if alert.get("kind").and_then(Value::as_str) == Some("diagnosis") {
                    inner.diagnoses.push(alert.clone());
                }
            }
        }
        let published = Arc::new(Published {
            seq,
            text: event.to_string(),
        });
        match kind {
            Kind::Meta => inner.meta = Some(published.clone()),
            Kind::State => inner.state = Some(published.clone()),
            Kind::Point => {
                inner.points.push_back(published.clone());
                if inner.points.len() > self.limits.points {
                    inner.points.pop_front();
                }
            }
            Kind::Other => {
                inner.events.push_back(published.clone());
                if inner.events.len() > self.limits.events {
                    inner.events.pop_front();
                }
            }
        }
        let mut dropped = 0;
        inner.clients.retain(|client| {
            match client.try_send(published.clone()) {
                Ok(()) => true,
                Err(mpsc::error::TrySendError::Closed(_)) => false,
                Err(mpsc::error::TrySendError::Full(_)) => {
                    // Dropping the sender ends the client's stream; its browser reconnects.
                    dropped += 1;
                    false
                }
            }
        });
        drop(inner);
        self.published.fetch_add(1, Ordering::Relaxed);
        if dropped > 0 {
            self.dropped_clients.fetch_add(dropped, Ordering::Relaxed);
            self.dropped_events.fetch_add(dropped, Ordering::Relaxed);
        }
    }

    /// A new client: the history in order, then what comes. None when `Limits::clients` are
    /// served already.
    pub fn subscribe(&self) -> Option<Subscription> {
        let mut inner = self.lock();
        inner.clients.retain(|c| !c.is_closed());
        if inner.clients.len() >= self.limits.clients {
            return None;
        }
        let mut history: Vec<Arc<Published>> = inner
            .points
            .iter()
            .chain(&inner.events)
            .chain(&inner.state)
            .cloned()
            .collect();
        history.sort_by_key(|p| p.seq);
        if let Some(meta) = &inner.meta {
            history.insert(0, meta.clone());
        }
        let (send, live) = mpsc::channel(self.limits.queue);
        inner.clients.push(send);
        Some(Subscription { history, live })
    }

    /// Whether the watch raised an alert with this sequence number (among the last
    /// `Limits::events`).
    pub fn has_alert(&self, seq: u64) -> bool {
        self.lock().alert_seqs.contains(&seq)
    }

    /// The diagnoses' alerts so far, in order.
    pub fn diagnoses(&self) -> Vec<Value> {
        self.lock().diagnoses.clone()
    }

    pub fn stats(&self) -> Stats {
        let clients = {
            let mut inner = self.lock();
            inner.clients.retain(|c| !c.is_closed());
            inner.clients.len()
        };
        Stats {
            published: self.published.load(Ordering::Relaxed),
            dropped_clients: self.dropped_clients.load(Ordering::Relaxed),
            dropped_events: self.dropped_events.load(Ordering::Relaxed),
            clients,
        }
    }
}
