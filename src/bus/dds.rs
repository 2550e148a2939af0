//! The DDS transport of the robot's bus: a participant confined to one network, typed writers
//! and readers of the bus's messages, and a reader one can block on with a deadline.
//!
//! DDS is `rustdds` (pure Rust). It interoperates with the CycloneDDS 0.10.2 of Unitree's
//! robots: it matches Cyclone by type name and sends no XTypes type object, and it speaks XCDR1,
//! which is what Cyclone 0.10.2 sends for these final types (docs/bus.md, "Why rustdds").
//!
//! Network: [`participant`] announces and listens on the configured interface only. On the
//! loopback (the default, and every test) it discovers peers by unicast to 127.0.0.1 and never
//! joins or sends multicast. Its sockets still bind 0.0.0.0: this is not an access control.

use std::marker::PhantomData;
use std::net::IpAddr;
use std::time::{Duration, Instant};

use rustdds::mio1::{Events, Interest, Poll, Token};
use rustdds::no_key::{
    DataWriter, Decode, DefaultDecoder, DeserializerAdapter, SerializerAdapter, SimpleDataReader,
};
use rustdds::{
    DomainParticipant, DomainParticipantBuilder, QosPolicies, QosPolicyBuilder, RTPSEntity,
    RepresentationIdentifier, StatusEvented, TopicKind, policy,
};

use super::unitree_hg::{CDR_LE, LowCmd, LowState, WireError};

/// Why the bus cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum DdsError {
    #[error("DDS participant on domain {domain}, interface {interface}: {reason}")]
    Participant {
        domain: u16,
        interface: IpAddr,
        reason: String,
    },
    #[error("DDS topic `{topic}`: {reason}")]
    Endpoint { topic: String, reason: String },
    #[error("DDS write on `{topic}`: {reason}")]
    Write { topic: String, reason: String },
    #[error("DDS read on `{topic}`: {reason}")]
    Read { topic: String, reason: String },
}

/// Where the participant lives: the DDS domain and the one interface it uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BusNetwork {
    pub domain: u16,
    /// The interface's address: 127.0.0.1 for a simulator on this machine, the robot's network
    /// (e.g. 192.168.123.x on a G1's wired link) for a robot.
    pub interface: IpAddr,
}

/// A participant announcing and listening on `net.interface` only.
pub fn participant(net: BusNetwork) -> Result<DomainParticipant, DdsError> {
    DomainParticipantBuilder::new(net.domain)
        .with_only_networks([net.interface])
        // Unicast discovery of peers on 127.0.0.1 (no multicast is needed on one machine).
        .same_host_loopback(net.interface.is_loopback())
        .build()
        .map_err(|e| DdsError::Participant {
            domain: net.domain,
            interface: net.interface,
            reason: e.to_string(),
        })
}

/// Whether a participant's own threads still run. rustdds (0.15) ends its event loop and its
/// discovery thread on the first interrupted poll, and on Linux a thread blocked in
/// `epoll_wait` is interrupted (EINTR) whenever its process is stopped and continued, with or
/// without a handler (signal(7)): a debugger, Ctrl-Z, a paused container. The participant then
/// neither sends nor receives and says nothing; only its threads' absence shows it.
#[derive(Debug, Clone, Copy)]
pub struct Liveness {
    /// rustdds's named threads in this process once the participant was built.
    threads: usize,
}

/// The kernel keeps 15 bytes of a thread's name: rustdds names its event loop
/// "RustDDS Participant N event loop" and its discovery "RustDDS discovery thread".
const LIBRARY_THREAD: &str = "RustDDS ";

/// rustdds's named threads in this process (`None` without a readable /proc).
fn library_threads() -> Option<usize> {
    let tasks = std::fs::read_dir("/proc/self/task").ok()?;
    Some(
        tasks
            .filter_map(|t| std::fs::read_to_string(t.ok()?.path().join("comm")).ok())
            .filter(|name| name.starts_with(LIBRARY_THREAD))
            .count(),
    )
}

impl Liveness {
    /// Taken right after the process's participant is built (one participant per process).
    pub fn of_new_participant() -> Self {
        Self {
            threads: library_threads().unwrap_or(0),
        }
    }

    /// Whether one of the participant's threads has ended (false when it cannot be known).
    /// Reads /proc and allocates: for when the bus has gone silent, never for every sample.
    pub fn ended(&self) -> bool {
        library_threads().is_some_and(|n| n < self.threads)
    }
}

/// Writer QoS of Unitree's SDK: reliable, last sample only, nothing kept for late joiners.
pub fn writer_qos() -> QosPolicies {
    QosPolicyBuilder::new()
        .reliability(policy::Reliability::Reliable {
            max_blocking_time: rustdds::Duration::from_millis(1),
        })
        .history(policy::History::KeepLast { depth: 1 })
        .durability(policy::Durability::Volatile)
        .build()
}

/// Reader QoS of Unitree's SDK: best effort, last sample only (a late sample is worth nothing).
pub fn reader_qos() -> QosPolicies {
    QosPolicyBuilder::new()
        .reliability(policy::Reliability::BestEffort)
        .history(policy::History::KeepLast { depth: 1 })
        .durability(policy::Durability::Volatile)
        .build()
}

/// A message with its own XCDR1 little-endian encoding (the body after the 4-byte header).
pub trait BusMessage: Sized + 'static {
    /// The DDS type name peers match on.
    const TYPE_NAME: &'static str;
    /// The body, appended to `out`.
    fn encode_body(&self, out: &mut Vec<u8>);
    fn decode_body(body: &[u8]) -> Result<Self, WireError>;
}

impl BusMessage for LowState {
    const TYPE_NAME: &'static str = super::unitree_hg::LOW_STATE_TYPE_NAME;
    fn encode_body(&self, out: &mut Vec<u8>) {
        self.encode_cdr(out);
        out.drain(..CDR_LE.len());
    }
    fn decode_body(body: &[u8]) -> Result<Self, WireError> {
        LowState::decode_body(body)
    }
}

impl BusMessage for LowCmd {
    const TYPE_NAME: &'static str = super::unitree_hg::LOW_CMD_TYPE_NAME;
    fn encode_body(&self, out: &mut Vec<u8>) {
        self.encode_cdr(out);
        out.drain(..CDR_LE.len());
    }
    fn decode_body(body: &[u8]) -> Result<Self, WireError> {
        LowCmd::decode_body(body)
    }
}

/// rustdds's (de)serializer adapter for a [`BusMessage`]: the message's own encoding, not serde.
pub struct Xcdr1<M>(PhantomData<M>);

/// The adapters' decoder (stateless).
pub struct Xcdr1Decoder<M>(PhantomData<M>);

// Not derived: a derive would ask `M: Clone`, which the decoder does not need.
impl<M> Clone for Xcdr1Decoder<M> {
    fn clone(&self) -> Self {
        Xcdr1Decoder(PhantomData)
    }
}

impl<M: BusMessage> SerializerAdapter<M> for Xcdr1<M> {
    type Error = std::convert::Infallible;
    fn output_encoding() -> RepresentationIdentifier {
        RepresentationIdentifier::CDR_LE
    }
    fn to_bytes(value: &M) -> Result<rustdds::bytes::Bytes, Self::Error> {
        let mut out = Vec::new();
        value.encode_body(&mut out);
        Ok(out.into())
    }
}

const XCDR1_LE: [RepresentationIdentifier; 1] = [RepresentationIdentifier::CDR_LE];

impl<M: BusMessage> DeserializerAdapter<M> for Xcdr1<M> {
    type Error = WireError;
    type Decoded = M;
    fn supported_encodings() -> &'static [RepresentationIdentifier] {
        &XCDR1_LE
    }
    fn transform_decoded(decoded: M) -> M {
        decoded
    }
}

impl<'de, M: BusMessage> Decode<'de, M> for Xcdr1Decoder<M> {
    type Error = WireError;
    fn decode_bytes(self, body: &'de [u8], _: RepresentationIdentifier) -> Result<M, WireError> {
        M::decode_body(body)
    }
}

impl<M: BusMessage> DefaultDecoder<M> for Xcdr1<M> {
    type Decoder = Xcdr1Decoder<M>;
    const DECODER: Self::Decoder = Xcdr1Decoder(PhantomData);
}

/// A typed writer on one topic.
pub struct Outbox<M: BusMessage> {
    writer: DataWriter<M, Xcdr1<M>>,
    topic: String,
}

/// Why an endpoint of `topic` could not be made.
fn endpoint_error(topic: &str, e: impl std::fmt::Display) -> DdsError {
    DdsError::Endpoint {
        topic: topic.into(),
        reason: e.to_string(),
    }
}

/// Topic `name` of `M`'s type, keyless, with `qos`.
fn topic_of<M: BusMessage>(
    dp: &DomainParticipant,
    name: &str,
    qos: &QosPolicies,
) -> Result<rustdds::Topic, DdsError> {
    dp.create_topic(name.into(), M::TYPE_NAME.into(), qos, TopicKind::NoKey)
        .map_err(|e| endpoint_error(name, e))
}

impl<M: BusMessage> Outbox<M> {
    pub fn new(dp: &DomainParticipant, topic: &str) -> Result<Self, DdsError> {
        let err = |e: rustdds::dds::CreateError| endpoint_error(topic, e);
        let qos = writer_qos();
        let t = topic_of::<M>(dp, topic, &qos)?;
        let writer = dp
            .create_publisher(&qos)
            .map_err(err)?
            .create_datawriter_no_key::<M, Xcdr1<M>>(&t, Some(qos))
            .map_err(err)?;
        Ok(Self {
            writer,
            topic: topic.into(),
        })
    }

    pub fn write(&self, msg: M) -> Result<(), DdsError> {
        self.writer.write(msg, None).map_err(|e| DdsError::Write {
            topic: self.topic.clone(),
            reason: e.to_string(),
        })
    }
}

/// A typed reader on one topic that one can wait on with a deadline.
pub struct Inbox<M: BusMessage> {
    reader: SimpleDataReader<M, Xcdr1<M>>,
    poll: Poll,
    events: Events,
    topic: String,
    /// Samples that did not decode (another layout, truncated).
    pub undecodable: u64,
    /// Samples dropped unread because a newer one was there ([`Inbox::wait_newest`]).
    pub superseded: u64,
    /// Every writer ever matched that is not of `own` participant.
    foreign: Vec<rustdds::GUID>,
    own: rustdds::GUID,
}

impl<M: BusMessage> Inbox<M> {
    pub fn new(dp: &DomainParticipant, topic: &str) -> Result<Self, DdsError> {
        let qos = reader_qos();
        let t = topic_of::<M>(dp, topic, &qos)?;
        let mut reader = dp
            .create_subscriber(&qos)
            .map_err(|e| endpoint_error(topic, e))?
            .create_simple_datareader_no_key::<M, Xcdr1<M>>(&t, Some(qos))
            .map_err(|e| endpoint_error(topic, e))?;
        let poll = Poll::new().map_err(|e| endpoint_error(topic, e))?;
        poll.registry()
            .register(&mut reader, Token(0), Interest::READABLE)
            .map_err(|e| endpoint_error(topic, e))?;
        Ok(Self {
            reader,
            poll,
            events: Events::with_capacity(4),
            topic: topic.into(),
            undecodable: 0,
            superseded: 0,
            foreign: Vec::new(),
            own: dp.guid(),
        })
    }

    /// The next sample if one is here (undecodable ones are counted and skipped).
    pub fn try_take(&mut self) -> Result<Option<M>, DdsError> {
        loop {
            match self.reader.try_take_one() {
                Ok(Some(c)) => return Ok(Some(c.sample)),
                Ok(None) => return Ok(None),
                // A sample of another layout: counted, the next one may be fine.
                Err(rustdds::dds::ReadError::Deserialization { .. }) => self.undecodable += 1,
                Err(e) => {
                    return Err(DdsError::Read {
                        topic: self.topic.clone(),
                        reason: e.to_string(),
                    });
                }
            }
        }
    }

    /// The next sample, waiting until `deadline` at most.
    pub fn wait(&mut self, deadline: Instant) -> Result<Option<M>, DdsError> {
        loop {
            self.reader.drain_read_notifications();
            if let Some(m) = self.try_take()? {
                return Ok(Some(m));
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            // Readiness is edge-triggered: drained above, then checked again after the wait.
            let wait = (deadline - now).min(Duration::from_millis(50));
            match self.poll.poll(&mut self.events, Some(wait)) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => {
                    return Err(DdsError::Read {
                        topic: self.topic.clone(),
                        reason: e.to_string(),
                    });
                }
            }
        }
    }

    /// The newest sample, waiting until `deadline` for one at most; older ones still queued are
    /// dropped and counted in `superseded` (a late state is worth nothing: rustdds keeps more
    /// than the QoS's last one).
    pub fn wait_newest(&mut self, deadline: Instant) -> Result<Option<M>, DdsError> {
        let Some(mut newest) = self.wait(deadline)? else {
            return Ok(None);
        };
        while let Some(m) = self.try_take()? {
            newest = m;
            self.superseded += 1;
        }
        Ok(Some(newest))
    }

    /// How many distinct writers of other participants were ever matched (another controller
    /// on a command topic).
    pub fn foreign_writers(&mut self) -> usize {
        while let Some(s) = self.reader.try_recv_status() {
            if let rustdds::DataReaderStatus::SubscriptionMatched { writer, .. } = s
                && writer.prefix != self.own.prefix
                && !self.foreign.contains(&writer)
            {
                self.foreign.push(writer);
            }
        }
        self.foreign.len()
    }
}

/// A [`BusMessage`] encoded by serde's CDR (XCDR1 little endian): upc's own topics and ROS 2's
/// types, whose layout is their fields' in order.
macro_rules! serde_bus_message {
    ($msg:ty, $type_name:literal) => {
        impl $crate::bus::dds::BusMessage for $msg {
            const TYPE_NAME: &'static str = $type_name;
            fn encode_body(&self, out: &mut Vec<u8>) {
                // Plain structs of numbers, strings and sequences: serialising cannot fail.
                if let Ok(bytes) =
                    $crate::bus::dds::serde_cdr::to_vec::<_, byteorder::LittleEndian>(self)
                {
                    out.extend_from_slice(&bytes);
                }
            }
            fn decode_body(body: &[u8]) -> Result<Self, $crate::bus::unitree_hg::WireError> {
                $crate::bus::dds::serde_cdr::from_bytes::<Self, byteorder::LittleEndian>(body)
                    .map(|(m, _)| m)
                    .map_err(|_| $crate::bus::unitree_hg::WireError::Malformed {
                        type_name: $type_name,
                        got: body.len(),
                    })
            }
        }
    };
}
pub(crate) use serde_bus_message;

/// serde's CDR, as rustdds uses it.
pub use rustdds::cdr_encoding as serde_cdr;
