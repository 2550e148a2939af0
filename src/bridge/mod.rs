//! `upc bridge`: the contract's services between this host's iceoryx2 and Zenoh, for forecasters
//! and viewers on other hosts. Forecasts come in from Zenoh and are published on iceoryx2, so
//! the controller only ever sees iceoryx2 and never waits on a network; states, ground truth
//! and torques go out to Zenoh at a decimation.
//!
//! Two threads, each with its own iceoryx2 node: *inbound* takes forecasts from a bounded queue
//! that Zenoh's callback fills (a flood beyond it is dropped and counted, never buffered without
//! bound), checks each one's header and publishes it; *outbound* wakes on each state and puts
//! the decimated samples (Zenoh's default congestion control for data drops, so a slow network
//! never blocks it).
//!
//! Who may connect, and what each may do, is set by [`security`]; which source's forecasts are
//! taken, and how fast, by [`gate`].

mod config;
mod gate;
mod security;
pub mod wire;

use std::sync::Arc;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::time::{Duration, Instant};

use serde::Serialize;
use zenoh::Wait;

pub use config::{BRIDGE_TOML, BridgeConfig, ZenohMode};
use gate::{ForecastGate, Refusal};
use security::Keys;
pub use security::{Posture, SecurityConfig};
use wire::{WireError, WireMessage, decode_into, encode};

use crate::channels::{
    ChannelError, ContractNode, ForecastMsg, GroundTruthMsg, ServiceKind, StateMsg, TorqueMsg,
};
use crate::realtime::LatencyHistogram;

/// Why the bridge stopped.
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    #[error(
        "cannot open the Zenoh session ({mode}, listen {listen:?}, connect {connect:?}): {detail}"
    )]
    Open {
        mode: &'static str,
        listen: Vec<String>,
        connect: Vec<String>,
        detail: String,
    },
    #[error("Zenoh: {0}")]
    Zenoh(String),
    #[error(transparent)]
    Channel(#[from] ChannelError),
    #[error("cannot start the bridge's {what} thread: {detail}")]
    Spawn { what: &'static str, detail: String },
    #[error("a bridge thread panicked")]
    Panicked,
}

/// Forecasts refused, by reason ([`WireError::key`]).
#[derive(Debug, Default, Clone, Serialize, PartialEq, Eq)]
pub struct RefusedBy {
    pub not_upc: u64,
    pub version: u64,
    pub kind: u64,
    pub size: u64,
}

/// What the bridge did (its summary, `--summary`).
#[derive(Debug, Default, Clone, Serialize)]
pub struct BridgeSummary {
    pub key_prefix: String,
    pub prefix: String,
    pub mode: String,
    pub decimation: u32,
    /// How participants are identified (`mutual TLS`, … `INSECURE: …`).
    pub security: String,
    /// Plain TCP beyond loopback was accepted (`--insecure`).
    pub insecure: bool,
    /// Identities allowed to put forecasts, and to view.
    pub forecasters: Vec<String>,
    pub viewers: Vec<String>,
    /// Forecast payloads that arrived from Zenoh (past Zenoh's access control).
    pub forecasts_received: u64,
    /// Published on iceoryx2.
    pub forecasts_forwarded: u64,
    /// Refused by their header (another contract version, kind or size; not upc's).
    pub forecasts_refused: u64,
    pub forecasts_refused_by: RefusedBy,
    /// Dropped because `inbound_queue` forecasts were already waiting (a flood).
    pub forecasts_dropped: u64,
    /// Refused: another source's forecasts were being taken.
    pub forecasts_second_source: u64,
    /// Dropped: over `forecast_rate_hz` / `forecast_burst`.
    pub forecasts_rate_limited: u64,
    /// How many times a forecast source was taken (the first included), and the last one
    /// (its identity; empty: the anonymous key of plain loopback).
    pub forecast_sources_taken: u64,
    pub forecast_source: String,
    /// Zenoh callback → published on iceoryx2 (µs), over the forwarded forecasts.
    pub forward_p50_us: f64,
    pub forward_p99_us: f64,
    pub forward_max_us: f64,
    pub states_out: u64,
    pub ground_truth_out: u64,
    pub torques_out: u64,
    /// Puts Zenoh refused (a put never blocks: congestion drops silently in Zenoh).
    pub put_errors: u64,
    /// Most Zenoh peers (or routers) connected at once, and how often one left.
    pub peers_max: u64,
    pub peer_losses: u64,
    pub wall_seconds: f64,
    /// CPU time of the bridge process (user + system) over its wall time.
    pub cpu_seconds: f64,
    pub cpu_percent: f64,
}

/// A forecast payload as Zenoh delivered it, and when.
struct Inbound {
    bytes: Vec<u8>,
    at: Instant,
}

/// Counters the Zenoh callback updates (it runs on Zenoh's threads).
struct Intake {
    keys_prefix: String,
    gate: Mutex<ForecastGate>,
    received: AtomicU64,
    dropped: AtomicU64,
    second_source: AtomicU64,
    rate_limited: AtomicU64,
}

/// The inbound side while it runs: the Zenoh subscriber feeding the thread's queue, and the
/// thread.
type InboundSide = (
    zenoh::pubsub::Subscriber<()>,
    std::thread::JoinHandle<Result<InboundStats, BridgeError>>,
);

/// Run the bridge until `stop` is raised or a channel fails.
pub fn run(cfg: &BridgeConfig, stop: Arc<AtomicBool>) -> Result<BridgeSummary, BridgeError> {
    let start = Instant::now();
    let posture = cfg.posture().map_err(BridgeError::Zenoh)?;
    let session = open_session(cfg, posture)?;
    let intake = Arc::new(Intake::new(cfg));
    let inbound = if cfg.forecast_in {
        Some(start_inbound(cfg, &session, &intake, &stop)?)
    } else {
        None
    };
    let outbound = start_outbound(cfg, &session, &stop)?;

    let mut summary = BridgeSummary {
        key_prefix: cfg.key_prefix.clone(),
        prefix: cfg.prefix.clone(),
        mode: cfg.mode.name().into(),
        decimation: cfg.decimation,
        security: posture.name().into(),
        insecure: posture == Posture::Insecure,
        forecasters: cfg.security.forecasters.clone(),
        viewers: cfg.security.viewers.clone(),
        ..Default::default()
    };
    let out = outbound.join().map_err(|_| BridgeError::Panicked);
    // Whatever ended the outbound side ends the bridge.
    stop.store(true, Ordering::Relaxed);
    let inb = inbound.map(|(subscriber, thread)| {
        let r = thread.join().map_err(|_| BridgeError::Panicked);
        drop(subscriber);
        r
    });
    summary.add_outbound(&out??);
    if let Some(inb) = inb {
        summary.add_inbound(&inb??);
    }
    summary.add_intake(&intake);
    let _ = session.close().wait();
    summary.wall_seconds = start.elapsed().as_secs_f64();
    summary.cpu_seconds = process_cpu_seconds();
    summary.cpu_percent = 100.0 * summary.cpu_seconds / summary.wall_seconds.max(1e-9);
    Ok(summary)
}

/// The Zenoh session of `cfg`, opened (and what it is, logged).
fn open_session(cfg: &BridgeConfig, posture: Posture) -> Result<zenoh::Session, BridgeError> {
    let session = zenoh::open(cfg.zenoh().map_err(BridgeError::Zenoh)?)
        .wait()
        .map_err(|e| BridgeError::Open {
            mode: cfg.mode.name(),
            listen: cfg.listen.clone(),
            connect: cfg.connect.clone(),
            detail: e.to_string(),
        })?;
    tracing::info!(
        "bridge: iceoryx2 `{}` ⇄ Zenoh `{}/*` ({}, listening on {:?}, connecting to {:?}), outbound every {} steps; {}",
        cfg.prefix,
        cfg.key_prefix,
        cfg.mode.name(),
        cfg.listen,
        cfg.connect,
        cfg.decimation,
        posture.name()
    );
    if posture == Posture::Insecure {
        tracing::warn!(
            "bridge: INSECURE: plain TCP beyond loopback; any host that reaches {:?} can read the robot's state and publish forecasts",
            cfg.listen
        );
    }
    Ok(session)
}

impl Intake {
    /// Nothing counted yet; the gate as `cfg` sets it.
    fn new(cfg: &BridgeConfig) -> Intake {
        Intake {
            keys_prefix: cfg.key_prefix.clone(),
            gate: Mutex::new(ForecastGate::new(
                cfg.forecast_rate_hz,
                cfg.forecast_burst,
                Duration::from_secs_f64(cfg.source_takeover),
            )),
            received: AtomicU64::new(0),
            dropped: AtomicU64::new(0),
            second_source: AtomicU64::new(0),
            rate_limited: AtomicU64::new(0),
        }
    }
}

/// The inbound side: Zenoh's forecasts into a bounded queue ([`on_forecast`]), and the thread
/// that publishes them on iceoryx2 ([`forward_forecasts`]).
fn start_inbound(
    cfg: &BridgeConfig,
    session: &zenoh::Session,
    intake: &Arc<Intake>,
    stop: &Arc<AtomicBool>,
) -> Result<InboundSide, BridgeError> {
    let (tx, rx) = std::sync::mpsc::sync_channel::<Inbound>(cfg.inbound_queue);
    let subscriber = {
        let intake = Arc::clone(intake);
        let keys = Keys {
            prefix: &cfg.key_prefix,
        };
        session
            .declare_subscriber(keys.forecasts())
            .callback(move |sample| {
                on_forecast(
                    &tx,
                    &intake,
                    sample.key_expr().as_str(),
                    sample.payload().to_bytes(),
                )
            })
            .wait()
            .map_err(|e| BridgeError::Zenoh(format!("subscribe to forecasts: {e}")))?
    };
    let prefix = cfg.prefix.clone();
    let stop = Arc::clone(stop);
    let thread = std::thread::Builder::new()
        .name("bridge-in".into())
        .spawn(move || forward_forecasts(&prefix, &rx, &stop))
        .map_err(|e| BridgeError::Spawn {
            what: "inbound",
            detail: e.to_string(),
        })?;
    Ok((subscriber, thread))
}

/// The outbound side's thread ([`forward_outbound`]).
fn start_outbound(
    cfg: &BridgeConfig,
    session: &zenoh::Session,
    stop: &Arc<AtomicBool>,
) -> Result<std::thread::JoinHandle<Result<OutboundStats, BridgeError>>, BridgeError> {
    let session = session.clone();
    let cfg = cfg.clone();
    let stop = Arc::clone(stop);
    std::thread::Builder::new()
        .name("bridge-out".into())
        .spawn(move || forward_outbound(&cfg, &session, &stop))
        .map_err(|e| BridgeError::Spawn {
            what: "outbound",
            detail: e.to_string(),
        })
}

impl BridgeSummary {
    /// What the outbound thread put.
    fn add_outbound(&mut self, out: &OutboundStats) {
        self.states_out = out.states;
        self.ground_truth_out = out.truth;
        self.torques_out = out.torques;
        self.put_errors = out.put_errors;
        self.peers_max = out.peers_max;
        self.peer_losses = out.peer_losses;
    }

    /// What the inbound thread forwarded or refused, and how fast.
    fn add_inbound(&mut self, inb: &InboundStats) {
        self.forecasts_forwarded = inb.forwarded;
        self.forecasts_refused_by = inb.refused_by.clone();
        self.forecasts_refused = inb.refused();
        let l = &inb.forward;
        self.forward_p50_us = l.quantile(0.5) * 1e6;
        self.forward_p99_us = l.quantile(0.99) * 1e6;
        self.forward_max_us = l.max() * 1e6;
    }

    /// What the Zenoh callback counted, and the forecast source the gate took last.
    fn add_intake(&mut self, intake: &Intake) {
        self.forecasts_received = intake.received.load(Ordering::Relaxed);
        self.forecasts_dropped = intake.dropped.load(Ordering::Relaxed);
        self.forecasts_second_source = intake.second_source.load(Ordering::Relaxed);
        self.forecasts_rate_limited = intake.rate_limited.load(Ordering::Relaxed);
        let g = intake
            .gate
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        self.forecast_sources_taken = g.sources_taken;
        self.forecast_source = g.source().unwrap_or_default().to_owned();
    }
}

/// Zenoh's callback: past the gate (one source, the rate), queue the payload for the inbound
/// thread; else count it refused or dropped.
fn on_forecast(
    tx: &SyncSender<Inbound>,
    intake: &Intake,
    key: &str,
    bytes: std::borrow::Cow<[u8]>,
) {
    intake.received.fetch_add(1, Ordering::Relaxed);
    let source = Keys {
        prefix: &intake.keys_prefix,
    }
    .source(key);
    // The gate's state stays consistent if a callback panicked holding it: take it back.
    let admitted = intake
        .gate
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .admit(source, Instant::now());
    if let Err(why) = admitted {
        let (counter, what) = match why {
            Refusal::SecondSource => (&intake.second_source, "from a second source"),
            Refusal::RateLimited => (&intake.rate_limited, "over the rate limit"),
        };
        let n = counter.fetch_add(1, Ordering::Relaxed) + 1;
        if n.is_power_of_two() {
            tracing::warn!("bridge: forecast {what} (key `{key}`) refused, {n} so far");
        }
        return;
    }
    let msg = Inbound {
        bytes: bytes.into_owned(),
        at: Instant::now(),
    };
    match tx.try_send(msg) {
        Ok(()) => {}
        Err(TrySendError::Full(_)) => {
            let n = intake.dropped.fetch_add(1, Ordering::Relaxed) + 1;
            if n.is_power_of_two() {
                tracing::warn!(
                    "bridge: forecast dropped, {n} so far (more arrive than are forwarded)"
                );
            }
        }
        // The inbound thread has ended: the bridge is stopping.
        Err(TrySendError::Disconnected(_)) => {}
    }
}

#[derive(Default)]
struct InboundStats {
    forwarded: u64,
    refused_by: RefusedBy,
    /// Zenoh callback → published on iceoryx2.
    forward: LatencyHistogram,
}

impl InboundStats {
    fn refused(&self) -> u64 {
        let r = &self.refused_by;
        r.not_upc + r.version + r.kind + r.size
    }

    fn refuse(&mut self, e: &WireError) {
        let r = &mut self.refused_by;
        match e {
            WireError::NotUpc(_) => r.not_upc += 1,
            WireError::Version { .. } => r.version += 1,
            WireError::Kind { .. } => r.kind += 1,
            WireError::Size { .. } => r.size += 1,
        }
        // Rate-limited: the 1st, 2nd, 4th… refusal.
        let n = self.refused();
        if n.is_power_of_two() {
            tracing::warn!("bridge: forecast refused: {e} ({n} refused so far)");
        }
    }
}

/// The inbound thread: check and publish each queued forecast.
fn forward_forecasts(
    prefix: &str,
    rx: &Receiver<Inbound>,
    stop: &AtomicBool,
) -> Result<InboundStats, BridgeError> {
    let node = ContractNode::open(prefix, &format!("upc-bridge-in-{}", std::process::id()))?;
    let publisher = node.publisher::<ForecastMsg>()?;
    let notifier = node.notifier(ServiceKind::Forecast)?;
    let mut stats = InboundStats::default();
    while !stop.load(Ordering::Relaxed) {
        let inbound = match rx.recv_timeout(Duration::from_millis(50)) {
            Ok(m) => m,
            Err(RecvTimeoutError::Timeout) => {
                // A controller that subscribed since the last forecast gets it now.
                publisher.update_connections()?;
                continue;
            }
            Err(RecvTimeoutError::Disconnected) => break,
        };
        // Decoded straight into the shared-memory sample, which is sent only if the bytes are
        // a forecast of this contract. The controller checks the content (finite, in time, in
        // order) as for any forecaster.
        if let Err(e) = publisher.try_send_with(|m| decode_into(&inbound.bytes, m))? {
            stats.refuse(&e);
            continue;
        }
        notifier.notify()?;
        stats.forwarded += 1;
        stats.forward.record(inbound.at.elapsed());
    }
    Ok(stats)
}

/// How often the outbound thread counts the connected Zenoh peers (for the log and the summary).
const PEER_CHECK: Duration = Duration::from_millis(100);

#[derive(Default)]
struct OutboundStats {
    states: u64,
    truth: u64,
    torques: u64,
    put_errors: u64,
    peers_max: u64,
    peer_losses: u64,
}

/// A Zenoh publisher of one kind.
struct Out {
    publisher: zenoh::pubsub::Publisher<'static>,
}

impl Out {
    fn declare(session: &zenoh::Session, key: String) -> Result<Out, BridgeError> {
        let publisher = session
            .declare_publisher(key.clone())
            .wait()
            .map_err(|e| BridgeError::Zenoh(format!("declare publisher `{key}`: {e}")))?;
        Ok(Out { publisher })
    }

    /// Encode and put `msg` (the buffer is handed to Zenoh); false if Zenoh refused it.
    fn put<T: WireMessage>(&self, msg: &T) -> bool {
        let mut buf = Vec::with_capacity(wire::HEADER_LEN + size_of::<T>());
        encode(msg, &mut buf);
        self.publisher.put(buf).wait().is_ok()
    }
}

/// The outbound thread: wake on each state, forward the decimated samples.
fn forward_outbound(
    cfg: &BridgeConfig,
    session: &zenoh::Session,
    stop: &AtomicBool,
) -> Result<OutboundStats, BridgeError> {
    let node = ContractNode::open(
        &cfg.prefix,
        &format!("upc-bridge-out-{}", std::process::id()),
    )?;
    let states = node.subscriber::<StateMsg>()?;
    let truth = node.subscriber::<GroundTruthMsg>()?;
    let torques = node.subscriber::<TorqueMsg>()?;
    let wake = node.listener(ServiceKind::State)?;
    let state_out = Out::declare(session, key(cfg, ServiceKind::State))?;
    let truth_out = Out::declare(session, key(cfg, ServiceKind::GroundTruth))?;
    let torque_out = Out::declare(session, key(cfg, ServiceKind::Torques))?;
    let d = u64::from(cfg.decimation);
    let mut s = OutboundStats::default();
    let mut session_id = 0u64;
    let mut peers = 0u64;
    let mut last_peer_check = Instant::now();
    let put = |ok: bool, n: &mut u64, errors: &mut u64| {
        if ok {
            *n += 1;
        } else {
            *errors += 1;
            if errors.is_power_of_two() {
                tracing::warn!("bridge: Zenoh refused a put ({errors} so far)");
            }
        }
    };
    while !stop.load(Ordering::Relaxed) {
        wake.wait(Duration::from_millis(20))?;
        // Every sample, oldest first: the decimation keeps the steps that are multiples of
        // `decimation` (a remote forecaster with a period of `decimation` steps sees each window
        // boundary), and a new plant run's first state.
        while let Some(st) = states.receive()? {
            let first = st.session != session_id;
            session_id = st.session;
            if cfg.state_out && (first || st.step % d == 0) {
                let ok = state_out.put(&st);
                put(ok, &mut s.states, &mut s.put_errors);
            }
        }
        while let Some(gt) = truth.receive()? {
            if cfg.ground_truth_out && gt.step % d == 0 {
                let ok = truth_out.put(&gt);
                put(ok, &mut s.truth, &mut s.put_errors);
            }
        }
        while let Some(tq) = torques.receive()? {
            if cfg.torques_out && tq.state_step % d == 0 {
                let ok = torque_out.put(&tq);
                put(ok, &mut s.torques, &mut s.put_errors);
            }
        }
        if last_peer_check.elapsed() >= PEER_CHECK {
            last_peer_check = Instant::now();
            let info = session.info();
            let now = info.peers_zid().wait().count() + info.routers_zid().wait().count();
            let now = now as u64;
            if now != peers {
                tracing::info!("bridge: {now} Zenoh peer(s) connected (were {peers})");
                if now < peers {
                    s.peer_losses += peers - now;
                }
                peers = now;
                s.peers_max = s.peers_max.max(now);
            }
        }
    }
    Ok(s)
}

/// The Zenoh key of a service: `<key_prefix>/<kind>`.
fn key(cfg: &BridgeConfig, kind: ServiceKind) -> String {
    format!("{}/{}", cfg.key_prefix, kind.suffix())
}

/// User + system CPU time of this process (s).
fn process_cpu_seconds() -> f64 {
    // SAFETY: getrusage fills the zeroed struct it is given.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) } != 0 {
        return f64::NAN;
    }
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    tv(u.ru_utime) + tv(u.ru_stime)
}
