//! The stream from an MQTT broker: `mqtt://HOST[:PORT]/TOPIC`. Each message holds one or more
//! CSV lines (`time,force,acc1,acc2,acc3` unless a header line in a message says otherwise).
//! The watcher subscribes with QoS 1 on a persistent session (clean session off, a client id
//! that stays the same from run to run), so what the broker keeps while the watcher is away —
//! the broker restarting, the network dropping, the watcher restarted — is delivered when it
//! is back. Alerts go to `TOPIC/alerts` with QoS 1, besides the alerts file.
//!
//! The protocol is rumqttc's; this module only turns its events into lines and reconnects.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use rumqttc::{Client, ConnectionError, Event, MqttOptions, Packet, QoS, RecvTimeoutError};

use super::WatchError;

/// Where an `mqtt://` source points.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MqttUrl {
    pub host: String,
    pub port: u16,
    pub topic: String,
}

impl MqttUrl {
    /// `mqtt://HOST[:PORT]/TOPIC` (port 1883 by default); None when `text` is not an MQTT URL.
    pub fn parse(text: &str) -> Option<Result<Self, WatchError>> {
        let rest = text.strip_prefix("mqtt://")?;
        let bad = |why: &str| {
            Some(Err(WatchError::Options(format!(
                "--source {text}: {why} (the form is mqtt://HOST[:PORT]/TOPIC)"
            ))))
        };
        let Some((address, topic)) = rest.split_once('/') else {
            return bad("no topic");
        };
        if topic.is_empty() || topic.contains(['+', '#']) {
            return bad("the topic must be one topic, without wildcards");
        }
        let (host, port) = match address.rsplit_once(':') {
            Some((host, port)) => match port.parse::<u16>() {
                Ok(p) if p > 0 => (host, p),
                _ => return bad(&format!("'{port}' is not a port")),
            },
            None => (address, 1883),
        };
        if host.is_empty() {
            return bad("no host");
        }
        Some(Ok(MqttUrl {
            host: host.to_owned(),
            port,
            topic: topic.to_owned(),
        }))
    }

    /// The topic alerts are published to.
    pub fn alerts_topic(&self) -> String {
        format!("{}/alerts", self.topic)
    }

    /// The default client id: the same for every watcher of this topic, so a restarted watcher
    /// takes over the session the broker kept.
    pub fn default_client_id(&self) -> String {
        let topic: String = self
            .topic
            .chars()
            .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
            .take(40)
            .collect();
        format!("twin-watch-{topic}")
    }
}

/// How the broker connection went, for the `end` alert.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct ConnectionStats {
    pub messages: u64,
    pub connections: u64,
    pub disconnections: u64,
    /// Messages the broker delivered again (the MQTT DUP flag).
    pub redelivered: u64,
}

/// The subscription and the alerts' publisher over one connection.
pub struct MqttSource {
    url: MqttUrl,
    client: Client,
    connection: rumqttc::Connection,
    lines: VecDeque<String>,
    /// Stop after this long without a message (None: never).
    idle: Option<Duration>,
    pub stats: ConnectionStats,
    /// Said once per disconnection, to the terminal.
    connected: bool,
    /// What happened to the connection since the watcher last asked (for its alerts).
    events: Vec<ConnectionEvent>,
}

/// A change of the broker connection the watcher reports as an alert.
#[derive(Debug, Clone)]
pub enum ConnectionEvent {
    Connected { session_present: bool },
    Lost { reason: String },
}

impl MqttSource {
    /// Connect and subscribe; returns at once (the connection is made as messages are read).
    pub fn open(
        url: MqttUrl,
        client_id: Option<String>,
        idle: Option<Duration>,
    ) -> Result<Self, WatchError> {
        let id = client_id.unwrap_or_else(|| url.default_client_id());
        let mut options = MqttOptions::new(id, url.host.clone(), url.port);
        options
            .set_clean_session(false)
            .set_keep_alive(Duration::from_secs(5))
            .set_max_packet_size(16 << 20, 1 << 20);
        let (client, connection) = Client::new(options, 4096);
        Ok(MqttSource {
            url,
            client,
            connection,
            lines: VecDeque::new(),
            idle,
            stats: ConnectionStats::default(),
            connected: false,
            events: Vec::new(),
        })
    }

    pub fn url(&self) -> &MqttUrl {
        &self.url
    }

    /// Connection changes since the last call.
    pub fn take_events(&mut self) -> Vec<ConnectionEvent> {
        std::mem::take(&mut self.events)
    }

    /// Queue `payload` on the alerts topic (QoS 1); sent as the connection is driven, kept
    /// while it is down.
    pub fn publish_alert(&mut self, payload: String) -> Result<(), WatchError> {
        self.client
            .try_publish(self.url.alerts_topic(), QoS::AtLeastOnce, false, payload)
            .map_err(|e| WatchError::Options(format!("cannot queue an MQTT alert: {e}")))
    }

    /// The next CSV line; None when `idle` passes without a message while connected (a
    /// broker away is not the stream's end). An empty line when the connection changed, so
    /// that the watcher reports it before the next message comes.
    pub fn next_line(&mut self) -> Result<Option<String>, WatchError> {
        let mut idle_since = Instant::now();
        loop {
            if let Some(line) = self.lines.pop_front() {
                return Ok(Some(line));
            }
            if !self.events.is_empty() {
                return Ok(Some(String::new()));
            }
            let wait = match self.idle {
                Some(idle) => idle
                    .saturating_sub(idle_since.elapsed())
                    .max(Duration::from_millis(50)),
                None => Duration::from_secs(3600),
            };
            match self.connection.recv_timeout(wait) {
                Err(RecvTimeoutError::Timeout) => {
                    if self.idle.is_some_and(|idle| idle_since.elapsed() >= idle) {
                        return Ok(None);
                    }
                }
                Err(RecvTimeoutError::Disconnected) => return Ok(None),
                Ok(Ok(event)) => {
                    let connected = self.connected;
                    if self.event(event)? || self.connected != connected {
                        idle_since = Instant::now();
                    }
                }
                Ok(Err(error)) => {
                    self.lost(error);
                    idle_since = Instant::now();
                }
            }
        }
    }

    /// Take one event; true when it brought a message.
    fn event(&mut self, event: Event) -> Result<bool, WatchError> {
        match event {
            Event::Incoming(Packet::ConnAck(ack)) => {
                self.connected = true;
                self.stats.connections += 1;
                if ack.session_present {
                    self.events.push(ConnectionEvent::Connected {
                        session_present: true,
                    });
                } else {
                    // A new session (the first, or the broker forgot it): subscribe again;
                    // connected once the broker has granted it.
                    self.client
                        .try_subscribe(self.url.topic.clone(), QoS::AtLeastOnce)
                        .map_err(|e| {
                            WatchError::Options(format!("cannot subscribe to the topic: {e}"))
                        })?;
                }
                Ok(false)
            }
            Event::Incoming(Packet::SubAck(ack)) => {
                if ack
                    .return_codes
                    .iter()
                    .any(|c| matches!(c, rumqttc::SubscribeReasonCode::Failure))
                {
                    return Err(WatchError::Options(format!(
                        "the broker refused the subscription to '{}'",
                        self.url.topic
                    )));
                }
                self.events.push(ConnectionEvent::Connected {
                    session_present: false,
                });
                Ok(false)
            }
            Event::Incoming(Packet::Publish(message)) if message.topic == self.url.topic => {
                self.stats.messages += 1;
                if message.dup {
                    self.stats.redelivered += 1;
                }
                let text = String::from_utf8_lossy(&message.payload);
                self.lines.extend(
                    text.lines()
                        .map(|l| l.trim_end_matches('\r').to_owned())
                        .filter(|l| !l.trim().is_empty()),
                );
                Ok(true)
            }
            _ => Ok(false),
        }
    }

    fn lost(&mut self, error: ConnectionError) {
        if self.connected {
            self.connected = false;
            self.stats.disconnections += 1;
            self.events.push(ConnectionEvent::Lost {
                reason: error.to_string(),
            });
        }
        // rumqttc reconnects on the next poll; wait a little between attempts.
        std::thread::sleep(Duration::from_millis(250));
    }

    /// Send what is queued (the last alerts) and disconnect, waiting at most `limit`.
    pub fn close(&mut self, limit: Duration) {
        if self.client.try_disconnect().is_err() {
            return;
        }
        let until = Instant::now() + limit;
        while let Some(left) = until.checked_duration_since(Instant::now()) {
            match self.connection.recv_timeout(left) {
                Ok(Ok(Event::Outgoing(rumqttc::Outgoing::Disconnect))) => return,
                Ok(Ok(_)) => {}
                Ok(Err(_)) | Err(_) => return,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mqtt_urls_are_read_and_bad_ones_are_refused_with_the_form() {
        let parse = |text: &str| MqttUrl::parse(text).expect("an mqtt:// URL");
        let url = parse("mqtt://127.0.0.1:18830/lab/frame/samples").expect("valid");
        assert_eq!(url.host, "127.0.0.1");
        assert_eq!(url.port, 18830);
        assert_eq!(url.topic, "lab/frame/samples");
        assert_eq!(url.alerts_topic(), "lab/frame/samples/alerts");
        assert_eq!(url.default_client_id(), "twin-watch-lab-frame-samples");
        assert_eq!(parse("mqtt://broker/t").expect("valid").port, 1883);
        assert!(MqttUrl::parse("data.csv").is_none());
        for bad in [
            "mqtt://host",
            "mqtt://host:x/t",
            "mqtt://:1883/t",
            "mqtt://h/a/#",
        ] {
            let e = parse(bad).expect_err("refused").to_string();
            assert!(
                e.contains(bad) && e.contains("mqtt://HOST[:PORT]/TOPIC"),
                "{e}"
            );
        }
    }
}
