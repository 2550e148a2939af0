//! Typed iceoryx2 endpoints for the contract's services.

use core::fmt::Debug;
use core::time::Duration;

use iceoryx2::node::NodeView;
use iceoryx2::port::listener::{Listener as IoxListener, ListenerWaitError};
use iceoryx2::port::notifier::Notifier as IoxNotifier;
use iceoryx2::port::publisher::Publisher as IoxPublisher;
use iceoryx2::port::subscriber::Subscriber as IoxSubscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::builder::publish_subscribe::{
    PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError,
};

use super::{Payload, ServiceKind};

/// Samples a subscriber buffers before the oldest is overwritten: a slow reader sees the newest.
const SUBSCRIBER_BUFFER: usize = 4;

/// What was being attempted when an IPC step failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChannelOp {
    NodeName,
    CreateNode,
    ServiceName,
    OpenService,
    OpenEvent,
    CreatePublisher,
    CreateSubscriber,
    CreateNotifier,
    CreateListener,
    Loan,
    Send,
    UpdateConnections,
    Receive,
    Notify,
    Wait,
}

impl core::fmt::Display for ChannelOp {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            ChannelOp::NodeName => "node name",
            ChannelOp::CreateNode => "create node",
            ChannelOp::ServiceName => "service name",
            ChannelOp::OpenService => "open service",
            ChannelOp::OpenEvent => "open event",
            ChannelOp::CreatePublisher => "create publisher",
            ChannelOp::CreateSubscriber => "create subscriber",
            ChannelOp::CreateNotifier => "create notifier",
            ChannelOp::CreateListener => "create listener",
            ChannelOp::Loan => "loan sample",
            ChannelOp::Send => "send sample",
            ChannelOp::UpdateConnections => "update connections",
            ChannelOp::Receive => "receive",
            ChannelOp::Notify => "notify",
            ChannelOp::Wait => "wait",
        })
    }
}

/// An IPC failure: what was attempted, on which node or service, and iceoryx2's own error
/// (typed: `source` downcasts to it).
#[derive(Debug, Clone)]
pub enum ChannelError {
    /// Another participant created the service with another layout of the payload (another
    /// contract version, or a mirror out of date).
    IncompatibleLayout {
        service: String,
        payload: &'static str,
        size: usize,
    },
    Ipc {
        op: ChannelOp,
        /// The node or service name, when the step concerns one.
        object: Option<String>,
        source: std::sync::Arc<dyn std::error::Error + Send + Sync>,
    },
}

impl ChannelError {
    /// What was being attempted.
    pub fn op(&self) -> ChannelOp {
        match self {
            ChannelError::IncompatibleLayout { .. } => ChannelOp::OpenService,
            ChannelError::Ipc { op, .. } => *op,
        }
    }

    /// A failure of `op` with a message of its own (no iceoryx2 error behind it).
    pub fn other(op: ChannelOp, message: impl Into<String>) -> Self {
        let message: String = message.into();
        ChannelError::Ipc {
            op,
            object: None,
            source: std::sync::Arc::from(Box::<dyn std::error::Error + Send + Sync>::from(message)),
        }
    }
}

impl core::fmt::Display for ChannelError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ChannelError::IncompatibleLayout {
                service,
                payload,
                size,
            } => write!(
                f,
                "open service `{service}`: another participant created it with another layout \
                 of `{payload}` than this process's ({size} bytes, MAX_DOF = {}, contract \
                 version {}): run every participant from the same upc version, or update the \
                 other's mirror of the contract (services/CHANNELS.md, \"Contract version\")",
                super::MAX_DOF,
                super::CONTRACT_VERSION
            ),
            ChannelError::Ipc {
                op,
                object: Some(o),
                source,
            } => write!(f, "{op} `{o}`: {source}"),
            ChannelError::Ipc {
                op,
                object: None,
                source,
            } => write!(f, "{op}: {source}"),
        }
    }
}

impl std::error::Error for ChannelError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            ChannelError::IncompatibleLayout { .. } => None,
            ChannelError::Ipc { source, .. } => Some(source.as_ref()),
        }
    }
}

fn err(op: ChannelOp, e: impl std::error::Error + Send + Sync + 'static) -> ChannelError {
    ChannelError::Ipc {
        op,
        object: None,
        source: std::sync::Arc::new(e),
    }
}

fn err_on(
    op: ChannelOp,
    object: impl Into<String>,
    e: impl std::error::Error + Send + Sync + 'static,
) -> ChannelError {
    ChannelError::Ipc {
        op,
        object: Some(object.into()),
        source: std::sync::Arc::new(e),
    }
}

/// One process's connection to the services of a prefix (one iceoryx2 node).
pub struct ContractNode {
    node: Node<ipc::Service>,
    prefix: String,
}

impl ContractNode {
    /// Open the contract's channels of `prefix` as node `node_name`. Stale resources of dead nodes (a process killed with
    /// SIGKILL) are removed first, so a restart never fails with "already exists".
    pub fn open(prefix: &str, node_name: &str) -> Result<ContractNode, ChannelError> {
        // iceoryx2's own logger: errors only unless IOX2_LOG_LEVEL says otherwise.
        set_log_level_from_env_or(LogLevel::Error);
        let removed = cleanup_dead_nodes();
        if removed > 0 {
            tracing::info!("removed stale iceoryx2 resources of {removed} dead node(s)");
        }
        let name: NodeName = node_name
            .try_into()
            .map_err(|e| err_on(ChannelOp::NodeName, node_name, e))?;
        let node = NodeBuilder::new()
            .name(&name)
            // Processes handle SIGINT/SIGTERM themselves (clean shutdown, complete logs).
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<ipc::Service>()
            .map_err(|e| err_on(ChannelOp::CreateNode, node_name, e))?;
        Ok(ContractNode {
            node,
            prefix: prefix.to_string(),
        })
    }

    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    fn service_name(&self, kind: ServiceKind, event: bool) -> Result<ServiceName, ChannelError> {
        let name = format!(
            "{}/{}{}",
            self.prefix,
            kind.suffix(),
            if event { "/event" } else { "" }
        );
        name.as_str()
            .try_into()
            .map_err(|e| err_on(ChannelOp::ServiceName, name.as_str(), e))
    }

    fn pubsub<T: ZeroCopySend + Debug + 'static>(
        &self,
        kind: ServiceKind,
    ) -> Result<PubSubService<T>, ChannelError> {
        let name = self.service_name(kind, false)?;
        self.node
            .service_builder(&name)
            .publish_subscribe::<T>()
            .history_size(kind.history())
            .subscriber_max_buffer_size(SUBSCRIBER_BUFFER)
            .enable_safe_overflow(true)
            .max_publishers(4)
            .max_subscribers(8)
            .max_nodes(16)
            .open_or_create()
            .map_err(|e| match e {
                PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
                    PublishSubscribeOpenError::IncompatibleTypes,
                ) => ChannelError::IncompatibleLayout {
                    service: name.to_string(),
                    payload: core::any::type_name::<T>()
                        .rsplit("::")
                        .next()
                        .unwrap_or("payload"),
                    size: core::mem::size_of::<T>(),
                },
                e => err_on(ChannelOp::OpenService, name.to_string(), e),
            })
    }

    fn event(
        &self,
        kind: ServiceKind,
    ) -> Result<iceoryx2::service::port_factory::event::PortFactory<ipc::Service>, ChannelError>
    {
        let name = self.service_name(kind, true)?;
        self.node
            .service_builder(&name)
            .event()
            .max_notifiers(4)
            .max_listeners(8)
            .max_nodes(16)
            .open_or_create()
            .map_err(|e| err_on(ChannelOp::OpenEvent, name.as_str(), e))
    }

    /// A publisher on `T`'s service.
    pub fn publisher<T: Payload>(&self) -> Result<Publisher<T>, ChannelError> {
        let inner = self
            .pubsub::<T>(T::KIND)?
            .publisher_builder()
            .create()
            .map_err(|e| err(ChannelOp::CreatePublisher, e))?;
        Ok(Publisher { inner })
    }

    /// A subscriber to `T`'s service.
    pub fn subscriber<T: Payload>(&self) -> Result<Subscriber<T>, ChannelError> {
        let service = self.pubsub::<T>(T::KIND)?;
        let inner = service
            .subscriber_builder()
            .create()
            .map_err(|e| err(ChannelOp::CreateSubscriber, e))?;
        Ok(Subscriber { inner, service })
    }

    pub fn notifier(&self, kind: ServiceKind) -> Result<Notifier, ChannelError> {
        let inner = self
            .event(kind)?
            .notifier_builder()
            .create()
            .map_err(|e| err(ChannelOp::CreateNotifier, e))?;
        Ok(Notifier { inner })
    }

    pub fn listener(&self, kind: ServiceKind) -> Result<Listener, ChannelError> {
        let inner = self
            .event(kind)?
            .listener_builder()
            .create()
            .map_err(|e| err(ChannelOp::CreateListener, e))?;
        Ok(Listener { inner })
    }
}

/// Remove the stale resources of dead iceoryx2 nodes; returns how many were cleaned.
pub fn cleanup_dead_nodes() -> usize {
    let mut removed = 0;
    let _ = Node::<ipc::Service>::list(Config::global_config(), |state| {
        if let NodeState::<ipc::Service>::Dead(view) = state
            && view.try_remove_stale_resources().is_ok()
        {
            removed += 1;
        }
        CallbackProgression::Continue
    });
    removed
}

/// Publishes `T` by loaning shared memory and filling it in place (no copy of the payload).
pub struct Publisher<T: ZeroCopySend + Debug + Copy + 'static> {
    inner: IoxPublisher<ipc::Service, T, ()>,
}

impl<T: ZeroCopySend + Debug + Copy + 'static> Publisher<T> {
    /// Loan a zeroed sample, let `fill` write it, send it.
    pub fn send_with(&self, fill: impl FnOnce(&mut T)) -> Result<(), ChannelError> {
        let Ok(()) = self.try_send_with(|m| {
            fill(m);
            Ok::<(), std::convert::Infallible>(())
        })?;
        Ok(())
    }

    /// As [`Publisher::send_with`], but `fill` may refuse: the sample is then returned to the
    /// pool unsent and its error handed back. For payloads decoded straight into shared memory.
    pub fn try_send_with<E>(
        &self,
        fill: impl FnOnce(&mut T) -> Result<(), E>,
    ) -> Result<Result<(), E>, ChannelError> {
        let mut sample = self
            .inner
            .loan_uninit()
            .map_err(|e| err(ChannelOp::Loan, e))?;
        // SAFETY: the contract's payloads are plain old data of integers and floats, for which
        // all-zero bytes are a valid value.
        let mut sample = unsafe {
            sample.payload_mut().as_mut_ptr().write_bytes(0, 1);
            sample.assume_init()
        };
        if let Err(e) = fill(sample.payload_mut()) {
            return Ok(Err(e));
        }
        sample.send().map_err(|e| err(ChannelOp::Send, e))?;
        Ok(Ok(()))
    }

    /// Send a copy of `msg`.
    pub fn send(&self, msg: &T) -> Result<(), ChannelError> {
        self.send_with(|m| *m = *msg)
    }

    /// Connect subscribers that appeared since the last send and hand them the history (a
    /// publisher otherwise does so only when it sends): for publishers that send rarely.
    pub fn update_connections(&self) -> Result<(), ChannelError> {
        use iceoryx2::port::update_connections::UpdateConnections;
        self.inner
            .update_connections()
            .map_err(|e| err(ChannelOp::UpdateConnections, e))
    }
}

type PubSubService<T> =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, ()>;

/// Receives `T`.
pub struct Subscriber<T: ZeroCopySend + Debug + Copy + 'static> {
    inner: IoxSubscriber<ipc::Service, T, ()>,
    service: PubSubService<T>,
}

impl<T: ZeroCopySend + Debug + Copy + 'static> Subscriber<T> {
    /// Whether a publisher of a living process is connected to the service: the peer is slow,
    /// not gone. A process killed with SIGKILL leaves its publisher registered until someone
    /// cleans up, but its node is then dead; a node whose state cannot be read counts as alive.
    /// Lists the system's nodes (allocates, touches the file system): for time-out paths only.
    pub fn has_live_publisher(&self) -> bool {
        let mut nodes = Vec::new();
        self.service.dynamic_config().list_publishers(|p| {
            nodes.push(p.node_id);
            CallbackProgression::Continue
        });
        if nodes.is_empty() {
            return false;
        }
        let mut alive = false;
        let listed = Node::<ipc::Service>::list(Config::global_config(), |node| {
            alive = match &node {
                NodeState::Alive(v) => nodes.contains(v.id()),
                NodeState::Inaccessible(id) => nodes.contains(id),
                NodeState::Dead(_) | NodeState::Undefined(_) => false,
            };
            if alive {
                CallbackProgression::Stop
            } else {
                CallbackProgression::Continue
            }
        });
        listed.is_ok() && alive
    }

    /// The next sample in order, copied out.
    pub fn receive(&self) -> Result<Option<T>, ChannelError> {
        Ok(self
            .inner
            .receive()
            .map_err(|e| err(ChannelOp::Receive, e))?
            .map(|s| *s))
    }

    /// The newest sample, dropping older ones.
    pub fn latest(&self) -> Result<Option<T>, ChannelError> {
        let mut last = None;
        while let Some(s) = self
            .inner
            .receive()
            .map_err(|e| err(ChannelOp::Receive, e))?
        {
            last = Some(*s);
        }
        Ok(last)
    }

    /// Run `f` on the newest sample in shared memory without copying it (large payloads).
    pub fn with_latest<R>(&self, f: impl FnOnce(&T) -> R) -> Result<Option<R>, ChannelError> {
        let mut last = None;
        while let Some(s) = self
            .inner
            .receive()
            .map_err(|e| err(ChannelOp::Receive, e))?
        {
            last = Some(s);
        }
        Ok(last.map(|s| f(&s)))
    }

    /// Whether samples are waiting.
    pub fn has_samples(&self) -> bool {
        self.inner.has_samples().unwrap_or(false)
    }
}

/// Wakes the listeners of a service.
pub struct Notifier {
    inner: IoxNotifier<ipc::Service>,
}

impl Notifier {
    pub fn notify(&self) -> Result<(), ChannelError> {
        self.inner
            .notify()
            .map(|_| ())
            .map_err(|e| err(ChannelOp::Notify, e))
    }
}

/// Waits for a service's wake-ups.
pub struct Listener {
    inner: IoxListener<ipc::Service>,
}

impl Listener {
    /// Block up to `timeout` for a notification; true if one (or more) arrived. A wait
    /// interrupted by a signal returns false early, like a time-out: Linux ends timed waits
    /// with EINTR when a stopped process is continued (SIGSTOP/SIGCONT: a debugger, job
    /// control, a freezer cgroup) even without a handler, and that is no reason to stop.
    pub fn wait(&self, timeout: Duration) -> Result<bool, ChannelError> {
        match self.inner.timed_wait(|_| {}, timeout) {
            Ok(n) => Ok(n > 0),
            Err(ListenerWaitError::InterruptSignal) => Ok(false),
            Err(e) => Err(err(ChannelOp::Wait, e)),
        }
    }

    /// Wait until `ready()` holds or a notification arrives, for at most `timeout`; true unless
    /// the time ran out. `ready` is first polled for up to `spin` without sleeping. Why: in
    /// lockstep the answer often comes within tens of µs (a simulator step), and waking a blocked
    /// process on a busy two-core machine costs tens to hundreds of µs (the scheduler's latency,
    /// not iceoryx2's). Spin only where the wait is short: a spinning waiter takes a core.
    /// Pending notifications are consumed first; a publisher sends its sample before notifying,
    /// so a notification consumed here belongs to a sample `ready` already sees.
    pub fn wait_until(
        &self,
        timeout: Duration,
        spin: Duration,
        mut ready: impl FnMut() -> bool,
    ) -> Result<bool, ChannelError> {
        self.drain()?;
        let start = std::time::Instant::now();
        loop {
            if ready() {
                return Ok(true);
            }
            let spent = start.elapsed();
            if spent >= spin.min(timeout) {
                return self.wait(timeout.saturating_sub(spent));
            }
            std::hint::spin_loop();
        }
    }

    /// Consume pending notifications without blocking; true if there were any.
    pub fn drain(&self) -> Result<bool, ChannelError> {
        let n = self
            .inner
            .try_wait(|_| {})
            .map_err(|e| err(ChannelOp::Wait, e))?;
        Ok(n > 0)
    }
}
