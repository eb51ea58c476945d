//! Notices: what the library has to say that is neither a result nor an error — an FMU's log
//! message, a live page that failed while the watch goes on. The library prints nothing: it
//! hands each notice to the sink its caller installed ([`set_sink`]; the `twin` binary's prints
//! them on stderr), and drops it when none is installed.

use std::sync::RwLock;

/// What a notice is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Topic {
    /// A message an FMU instance sent through its logger: `[instance] category: text`.
    FmuLog,
    /// The live page or its server failed; the watch goes on without it.
    LivePage,
}

/// One notice.
#[derive(Debug, Clone, PartialEq)]
pub struct Notice {
    pub topic: Topic,
    pub text: String,
}

type Sink = Box<dyn Fn(&Notice) + Send + Sync>;

static SINK: RwLock<Option<Sink>> = RwLock::new(None);

/// Where the process's notices go from now on (any thread's).
pub fn set_sink(sink: impl Fn(&Notice) + Send + Sync + 'static) {
    if let Ok(mut s) = SINK.write() {
        *s = Some(Box::new(sink));
    }
}

/// Hand a notice to the sink; `text` is made only when there is one.
pub fn notify(topic: Topic, text: impl FnOnce() -> String) {
    if let Ok(s) = SINK.read() {
        if let Some(sink) = s.as_ref() {
            sink(&Notice {
                topic,
                text: text(),
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    #[test]
    fn a_notice_reaches_the_installed_sink_and_its_text_is_made_only_then() {
        static SEEN: Mutex<Vec<Notice>> = Mutex::new(Vec::new());
        set_sink(|n| SEEN.lock().unwrap().push(n.clone()));
        notify(Topic::LivePage, || "the page stopped".to_owned());
        let seen = SEEN.lock().unwrap().clone();
        assert!(seen.contains(&Notice {
            topic: Topic::LivePage,
            text: "the page stopped".to_owned(),
        }));
        if let Ok(mut s) = SINK.write() {
            *s = None;
        }
        notify(Topic::LivePage, || panic!("no sink: the text is not made"));
    }
}
