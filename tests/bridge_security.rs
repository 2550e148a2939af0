//! Who gets through `upc bridge` (services/BRIDGE_SECURITY.md), on loopback: a real bridge
//! process with mutual TLS and the lab's CA made by `scripts/lab-pki.sh`, and Zenoh clients in
//! this process trying what an intruder, a viewer and forecasters would. Outcomes are asserted
//! by what arrives (on iceoryx2 behind the bridge, on the clients' subscribers) and by the
//! bridge's summary, never by durations.

mod support;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use support::procs::*;
use upc::bridge::wire::{decode_into, encode};
use upc::channels::{ContractNode, ForecastMsg, ServiceKind, StateMsg, TorqueMsg};
use zenoh::Wait;

/// The lab's CA, and certificates for the bridge, two forecasters and a viewer; plus a rogue CA
/// that issued a certificate under a forecaster's name.
fn pki(s: &Scratch) -> (PathBuf, PathBuf) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/lab-pki.sh");
    let run = |args: &[&str]| {
        let out = Command::new("bash")
            .arg(&script)
            .args(args)
            .output()
            .expect("bash");
        assert!(
            out.status.success(),
            "lab-pki {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    let (lab, rogue) = (s.path("pki"), s.path("rogue"));
    let (lab_s, rogue_s) = (lab.display().to_string(), rogue.display().to_string());
    run(&["ca", &lab_s]);
    for name in ["bridge", "fc1", "fc2", "viewer"] {
        run(&["issue", &lab_s, name]);
    }
    run(&["ca", &rogue_s, "rogue CA"]);
    run(&["issue", &rogue_s, "fc1"]);
    (lab, rogue)
}

/// The bridge's config file: the shipped example (services/bridge-tls.toml) with this test's
/// certificates, forecasters fc1 and fc2, one viewer, and `users` if given.
fn bridge_toml(s: &Scratch, pki: &Path, users: Option<&Path>) -> PathBuf {
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("services/bridge-tls.toml");
    let text = std::fs::read_to_string(shipped).expect("services/bridge-tls.toml");
    let users = users.map_or(String::new(), |u| u.display().to_string());
    let mut out = String::new();
    for line in text.lines() {
        let line = line
            .replace("/etc/upc/pki/", &format!("{}/", pki.display()))
            .replace("robot-bridge", "bridge");
        let key = line.split('=').next().unwrap_or("").trim();
        out += &match key {
            "forecasters" => "forecasters = [\"fc1\", \"fc2\"]".into(),
            "viewers" => "viewers = [\"viewer\"]".into(),
            "users" => format!("users = {users:?}"),
            // fc2 stays the second source however slow this machine is.
            "[bridge]" => "[bridge]\nsource_takeover = 5.0".into(),
            _ => line,
        };
        out.push('\n');
    }
    let path = s.path(if users.is_empty() {
        "bridge.toml"
    } else {
        "bridge_users.toml"
    });
    std::fs::write(&path, out).expect("bridge.toml");
    path
}

/// What a client shows the bridge.
#[derive(Clone, Copy, Default)]
struct Client<'a> {
    /// The CA it trusts (TLS), and its certificate (mutual TLS) from `dir`.
    ca: Option<&'a Path>,
    cert: Option<(&'a Path, &'a str)>,
    login: Option<(&'a str, &'a str)>,
}

impl Client<'_> {
    fn open(&self, endpoint: &str) -> Result<zenoh::Session, String> {
        let mut c = zenoh::Config::default();
        let mut set = |k: &str, v: serde_json::Value| {
            c.insert_json5(k, &v.to_string()).expect("client config");
        };
        set("mode", "client".into());
        set("connect/endpoints", serde_json::json!([endpoint]));
        set("scouting/multicast/enabled", false.into());
        set("transport/unicast/open_timeout", 3000.into());
        let tls = "transport/link/tls";
        if let Some(ca) = self.ca {
            set(
                &format!("{tls}/root_ca_certificate"),
                ca.join("ca.pem").display().to_string().into(),
            );
            set(&format!("{tls}/verify_name_on_connect"), true.into());
        }
        if let Some((dir, name)) = self.cert {
            let f = |ext: &str| dir.join(format!("{name}.{ext}")).display().to_string();
            set(&format!("{tls}/connect_certificate"), f("pem").into());
            set(&format!("{tls}/connect_private_key"), f("key").into());
            set(&format!("{tls}/enable_mtls"), true.into());
        }
        if let Some((user, password)) = self.login {
            set("transport/auth/usrpwd/user", user.into());
            set("transport/auth/usrpwd/password", password.into());
        }
        zenoh::open(c).wait().map_err(|e| e.to_string())
    }
}

/// A sample as a client's subscriber got it: its key and payload.
type Sample = (String, Vec<u8>);

/// Samples a client's subscribers got.
#[derive(Default, Clone)]
struct Got(Arc<Mutex<Vec<Sample>>>);

impl Got {
    fn subscribe(&self, session: &zenoh::Session, key: String) -> zenoh::pubsub::Subscriber<()> {
        let got = self.clone();
        session
            .declare_subscriber(key)
            .callback(move |s| {
                got.0.lock().unwrap().push((
                    s.key_expr().as_str().to_owned(),
                    s.payload().to_bytes().into_owned(),
                ))
            })
            .wait()
            .expect("subscriber")
    }

    fn count(&self, key_suffix: &str) -> usize {
        let v = self.0.lock().unwrap();
        v.iter().filter(|(k, _)| k.ends_with(key_suffix)).count()
    }

    /// Steps of the states received (what the bridge sent out, or a forged one).
    fn state_steps(&self) -> Vec<u64> {
        let v = self.0.lock().unwrap();
        let mut st = StateMsg::default();
        v.iter()
            .filter(|(k, _)| k.ends_with("/state"))
            .filter_map(|(_, b)| decode_into(b, &mut st).ok().map(|()| st.step))
            .collect()
    }

    /// The states these subscribers got of the test's own 20 (not its probes).
    fn states_below(&self, steps: u64) -> usize {
        self.state_steps().iter().filter(|&&s| s < steps).count()
    }

    /// The torques these subscribers got answering the test's own 20 states.
    fn torques_below(&self, steps: u64) -> usize {
        let v = self.0.lock().unwrap();
        let mut t = Box::<TorqueMsg>::default();
        v.iter()
            .filter(|(k, _)| k.ends_with("/torques"))
            .filter(|(_, b)| decode_into(b, t.as_mut()).is_ok() && t.state_step < steps)
            .count()
    }
}

fn window(seq: u64) -> Vec<u8> {
    let mut m = Box::<ForecastMsg>::default();
    (m.seq, m.t0, m.dt, m.len, m.period) = (seq, 0.0, 0.005, 10, 0.01);
    let mut buf = Vec::new();
    encode(m.as_ref(), &mut buf);
    buf
}

/// A publisher on `key`, once the bridge's subscription for it has reached this client: a
/// client drops a put for which it knows no subscriber, so a put before that is lost, not late.
fn matched(session: &zenoh::Session, key: String) -> zenoh::pubsub::Publisher<'static> {
    let publisher = session.declare_publisher(key).wait().expect("publisher");
    until(
        &format!("the bridge's subscription for {}", publisher.key_expr()),
        Duration::from_secs(10),
        || {
            publisher
                .matching_status()
                .wait()
                .is_ok_and(|m| m.matching())
        },
    );
    publisher
}

fn publish(publisher: &zenoh::pubsub::Publisher<'_>, bytes: Vec<u8>) {
    publisher.put(bytes).wait().expect("put");
    std::thread::sleep(Duration::from_millis(10));
}

fn put(session: &zenoh::Session, key: &str, bytes: Vec<u8>) {
    // The ACL refuses silently on the bridge's side: a put always succeeds locally.
    session.put(key, bytes).wait().expect("put");
    std::thread::sleep(Duration::from_millis(10));
}

/// Polls `done` every 10 ms until it holds; fails after `limit`, naming `what` (a deadline for
/// a failure, not a timed assertion: a passing run returns as soon as it holds).
fn until(what: &str, limit: Duration, mut done: impl FnMut() -> bool) {
    let deadline = Instant::now() + limit;
    while !done() {
        assert!(Instant::now() < deadline, "{what}: not within {limit:?}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// A put refused by Zenoh's access control leaves nothing to wait for: one that slipped
/// through would reach the bridge's callback within this (loopback, microseconds), and be
/// counted in its summary.
const REFUSED_PUT_GRACE: Duration = Duration::from_millis(300);

/// Steps above this are the test's probes (declarations crossing, barriers), not its states.
const PROBE: u64 = 1_000_000;

const FORGED_STEP: u64 = 777_777;

#[test]
fn only_the_labs_identities_get_through_and_each_only_where_its_role_allows() {
    let _serial = serial();
    let s = Scratch::new("bridge_security");
    let (lab, rogue) = pki(&s);
    let kp = s.prefix.clone();
    let endpoint = format!("tls/127.0.0.1:{}", free_port());
    let conf = bridge_toml(&s, &lab, None).display().to_string();
    let summary = s.path("bridge.json").display().to_string();
    let mut p = Procs::default();
    #[rustfmt::skip]
    p.start(&s, "bridge", &["bridge", "--prefix", &kp, "--listen", &endpoint, "--config", &conf,
                            "--set", "bridge.decimation=1", "--summary", &summary]);
    // Behind the bridge, as the controller and the plant: forecasts in, states and torques out.
    let node = ContractNode::open(&kp, "bridge-security-test").expect("contract node");
    let forecasts = node
        .subscriber::<ForecastMsg>()
        .expect("forecast subscriber");
    let states = node.publisher::<StateMsg>().expect("state");
    let wake = node.notifier(ServiceKind::State).expect("state notifier");
    let torques = node.publisher::<TorqueMsg>().expect("torques");

    let fc1 = Client {
        ca: Some(&lab),
        cert: Some((&lab, "fc1")),
        login: None,
    };
    // Wait for the bridge to listen: the forecaster's first session.
    let mut tries = 0;
    let fc1_session = loop {
        match fc1.open(&endpoint) {
            Ok(session) => break session,
            Err(e) => {
                tries += 1;
                assert!(
                    tries < 60,
                    "the bridge never accepted fc1: {e}\n{}",
                    log(&s, "bridge")
                );
                std::thread::sleep(Duration::from_millis(250));
            }
        }
    };

    // Refused at the connection: each one's error is kept for the table.
    let plain = format!("tcp/{}", endpoint.trim_start_matches("tls/"));
    let attempts = [
        (
            "plain TCP to the TLS port",
            Client::default(),
            plain.as_str(),
        ),
        (
            "TLS without a client certificate",
            Client {
                ca: Some(&lab),
                ..Client::default()
            },
            endpoint.as_str(),
        ),
        (
            "a certificate from another CA under fc1's name",
            Client {
                ca: Some(&lab),
                cert: Some((&rogue, "fc1")),
                login: None,
            },
            endpoint.as_str(),
        ),
    ];
    for (who, client, ep) in attempts {
        let r = client.open(ep);
        assert!(r.is_err(), "{who}: connected");
        eprintln!("refused: {who}: {}", r.err().unwrap_or_default());
    }

    let viewer = Client {
        ca: Some(&lab),
        cert: Some((&lab, "viewer")),
        login: None,
    }
    .open(&endpoint)
    .expect("the viewer connects");
    let fc2 = Client {
        ca: Some(&lab),
        cert: Some((&lab, "fc2")),
        login: None,
    }
    .open(&endpoint)
    .expect("fc2 connects");
    let (viewer_got, fc1_got) = (Got::default(), Got::default());
    let _v = [
        viewer_got.subscribe(&viewer, format!("{kp}/state")),
        viewer_got.subscribe(&viewer, format!("{kp}/torques")),
        fc1_got.subscribe(&fc1_session, format!("{kp}/state")),
        fc1_got.subscribe(&fc1_session, format!("{kp}/torques")),
    ];
    // The plant's side: a state and its torques, sent out to whoever may see them.
    let plant_tick = |step: u64| {
        states
            .send(&StateMsg {
                step,
                ..StateMsg::default()
            })
            .expect("state");
        torques
            .send(&TorqueMsg {
                state_step: step,
                ..TorqueMsg::default()
            })
            .expect("torques");
        wake.notify().expect("notify");
        std::thread::sleep(Duration::from_millis(10));
    };
    // The subscriptions crossed once probes reach both clients.
    let mut probe = PROBE;
    until(
        "the clients' subscriptions crossing",
        Duration::from_secs(10),
        || {
            probe += 1;
            plant_tick(probe);
            !viewer_got.state_steps().is_empty()
                && viewer_got.count("/torques") > 0
                && !fc1_got.state_steps().is_empty()
        },
    );

    // The viewer forges: a forecast on its own key, one on fc1's key, and a state.
    let mut forged = StateMsg {
        step: FORGED_STEP,
        ..StateMsg::default()
    };
    forged.time = 1.0;
    let mut forged_bytes = Vec::new();
    encode(&forged, &mut forged_bytes);
    for seq in 1..=5 {
        put(&viewer, &format!("{kp}/forecast/viewer"), window(seq));
        put(&viewer, &format!("{kp}/forecast/fc1"), window(100 + seq));
        put(&viewer, &format!("{kp}/forecast"), window(200 + seq));
        put(&viewer, &format!("{kp}/state"), forged_bytes.clone());
    }
    // fc1 forecasts on its key, then on fc2's key (refused: each forecaster its own key);
    // fc2, meanwhile, is the second source (refused while fc1 is alive).
    // The forecast service keeps a few samples (the controller reads the newest): drain it as
    // the windows arrive.
    let mut delivered = vec![];
    let drain = |delivered: &mut Vec<u64>| {
        while let Ok(Some(m)) = forecasts.receive() {
            delivered.push(m.seq);
        }
    };
    drain(&mut delivered);
    let fc1_key = matched(&fc1_session, format!("{kp}/forecast/fc1"));
    let fc2_key = matched(&fc2, format!("{kp}/forecast/fc2"));
    let fc1_windows = 20u64;
    for seq in 1..=fc1_windows {
        publish(&fc1_key, window(1000 + seq));
        publish(&fc2_key, window(2000 + seq));
        drain(&mut delivered);
    }
    put(&fc1_session, &format!("{kp}/forecast/fc2"), window(3000));
    // A barrier behind fc2's puts: its link delivers in order, so once a subscription it
    // declares after them has a state, the bridge has taken every one of its windows.
    let fc2_got = Got::default();
    let _barrier = fc2_got.subscribe(&fc2, format!("{kp}/state"));
    until(
        "fc2's subscription after its puts",
        Duration::from_secs(10),
        || {
            probe += 1;
            plant_tick(probe);
            !fc2_got.state_steps().is_empty()
        },
    );
    for step in 0..20u64 {
        plant_tick(step);
    }
    // fc1's windows all crossed (each in order on its link, before its refused put on fc2's
    // key), and the plant's last state reached both clients.
    until("fc1's windows on iceoryx2", Duration::from_secs(10), || {
        drain(&mut delivered);
        delivered.len() >= fc1_windows as usize
    });
    until(
        "the last state at the clients",
        Duration::from_secs(10),
        || viewer_got.state_steps().contains(&19) && fc1_got.state_steps().contains(&19),
    );
    drain(&mut delivered);
    drop(_barrier);
    drop(_v);
    for session in [viewer, fc2, fc1_session] {
        session.close().wait().expect("close");
    }
    p.stop(&s, "bridge", libc::SIGTERM);
    let b = json(&s.path("bridge.json"));
    let msg = format!("bridge {b}\n{}", log(&s, "bridge"));

    // Only fc1's own windows crossed to iceoryx2: nothing of the viewer's, nothing of fc2's.
    let want: Vec<u64> = (1001..=1000 + fc1_windows).collect();
    assert_eq!(delivered, want, "{msg}");
    assert_eq!(b["security"], "mutual TLS", "{msg}");
    assert_eq!(u(&b, "forecasts_forwarded"), fc1_windows, "{msg}");
    // Zenoh's access control stopped the viewer's forecasts and fc1's put on fc2's key before
    // the bridge's callback; fc2's reached it and were refused as a second source.
    assert_eq!(u(&b, "forecasts_received"), 2 * fc1_windows, "{msg}");
    assert_eq!(u(&b, "forecasts_second_source"), fc1_windows, "{msg}");
    assert_eq!(b["forecast_source"], "fc1", "{msg}");
    assert_eq!(u(&b, "forecast_sources_taken"), 1, "{msg}");
    // The viewer sees the state and the torques; fc1 the state only, never the viewer's
    // forged one (which only the viewer's own session delivers to itself).
    // (The bridge sends the newest state when it wakes: a slow wake-up may skip one, hence
    // 15 of 20 and not all.)
    let vs = viewer_got.state_steps();
    assert!(viewer_got.states_below(20) >= 15, "{vs:?} {msg}");
    assert!(viewer_got.torques_below(20) >= 15, "{msg}");
    let fs = fc1_got.state_steps();
    assert!(
        fc1_got.states_below(20) >= 15 && !fs.contains(&FORGED_STEP),
        "{fs:?} {msg}"
    );
    assert_eq!(fc1_got.count("/torques"), 0, "{msg}");
}

#[test]
fn with_passwords_on_top_a_wrong_or_missing_password_is_refused() {
    let _serial = serial();
    let s = Scratch::new("bridge_passwords");
    let (lab, _) = pki(&s);
    let users = s.path("users");
    std::fs::write(&users, "fc1:open sesame\nfc2:other\nviewer:view\n").expect("users");
    let conf = bridge_toml(&s, &lab, Some(&users)).display().to_string();
    let endpoint = format!("tls/127.0.0.1:{}", free_port());
    let summary = s.path("bridge.json").display().to_string();
    let mut p = Procs::default();
    #[rustfmt::skip]
    p.start(&s, "bridge", &["bridge", "--prefix", &s.prefix, "--listen", &endpoint,
                            "--config", &conf, "--summary", &summary]);
    let node = ContractNode::open(&s.prefix, "bridge-passwords-test").expect("contract node");
    let forecasts = node
        .subscriber::<ForecastMsg>()
        .expect("forecast subscriber");
    let with = |login| Client {
        ca: Some(&lab),
        cert: Some((&lab, "fc1")),
        login,
    };
    let mut tries = 0;
    let good = loop {
        match with(Some(("fc1", "open sesame"))).open(&endpoint) {
            Ok(session) => break session,
            Err(e) => {
                tries += 1;
                assert!(
                    tries < 60,
                    "fc1 with its password: {e}\n{}",
                    log(&s, "bridge")
                );
                std::thread::sleep(Duration::from_millis(250));
            }
        }
    };
    for (who, login) in [
        ("fc1 with a wrong password", Some(("fc1", "guess"))),
        ("fc1 with no password", None),
        (
            "fc1's certificate logging in as fc2",
            Some(("fc2", "other")),
        ),
    ] {
        let r = with(login).open(&endpoint);
        match r {
            // Another user than the certificate's name connects, but is nobody to the ACL.
            Ok(session) if who.contains("as fc2") => {
                put(&session, &format!("{}/forecast/fc2", s.prefix), window(7));
                put(&session, &format!("{}/forecast/fc1", s.prefix), window(8));
                session.close().wait().expect("close");
            }
            Ok(_) => panic!("{who}: connected"),
            Err(e) => eprintln!("refused: {who}: {e}"),
        }
    }
    std::thread::sleep(REFUSED_PUT_GRACE);
    publish(
        &matched(&good, format!("{}/forecast/fc1", s.prefix)),
        window(9),
    );
    // Behind the bridge, the good login's window arrives (and nothing before it).
    let mut delivered = vec![];
    until(
        "the good login's window on iceoryx2",
        Duration::from_secs(10),
        || {
            while let Ok(Some(m)) = forecasts.receive() {
                delivered.push(m.seq);
            }
            !delivered.is_empty()
        },
    );
    good.close().wait().expect("close");
    p.stop(&s, "bridge", libc::SIGTERM);
    let b = json(&s.path("bridge.json"));
    assert_eq!(delivered, [9], "{b}");
    assert_eq!(b["security"], "mutual TLS + user/password", "{b}");
    // Only the good login's window arrived.
    assert_eq!(u(&b, "forecasts_received"), 1, "{b}");
    assert_eq!(u(&b, "forecasts_forwarded"), 1, "{b}");
}

#[test]
fn plain_tcp_beyond_loopback_is_refused_unless_insecure() {
    let _serial = serial();
    let s = Scratch::new("bridge_insecure");
    let lan = format!("tcp/0.0.0.0:{}", free_port());
    let out = Command::new(env!("CARGO_BIN_EXE_upc"))
        .args(["bridge", "--prefix", &s.prefix, "--listen", &lan])
        .output()
        .expect("upc starts");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "listened on {lan} in plain TCP");
    assert!(err.contains("--insecure") && err.contains(&lan), "{err}");
    let summary = s.path("bridge.json").display().to_string();
    let mut p = Procs::default();
    #[rustfmt::skip]
    p.start(&s, "bridge", &["bridge", "--prefix", &s.prefix, "--listen", &lan, "--insecure",
                            "--summary", &summary]);
    until("the bridge's warning", Duration::from_secs(10), || {
        log(&s, "bridge").contains("INSECURE")
    });
    p.stop(&s, "bridge", libc::SIGTERM);
    let b = json(&s.path("bridge.json"));
    assert_eq!(b["insecure"], true, "{b}");
    assert!(
        log(&s, "bridge").contains("INSECURE"),
        "{}",
        log(&s, "bridge")
    );
}
