//! Latency the Zenoh bridge adds on loopback: a forecast put on Zenoh → the same window readable
//! on iceoryx2 (the bridge's callback, queue, header check, copy, publish and notify; Zenoh's
//! TCP on loopback). The bridge runs in this process; the controller's side is an iceoryx2
//! subscriber woken by the forecast event, as in the control loop. Besides criterion's
//! statistics, p50/p99 over 2000 round trips are printed. Twice: plain TCP (loopback's default)
//! and mutual TLS with the lab's CA (scripts/lab-pki.sh), to show what TLS adds.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use criterion::{Criterion, criterion_group, criterion_main};
use upc::bridge::{BridgeConfig, wire::encode};
use upc::channels::{ContractNode, ForecastMsg, ServiceKind};
use zenoh::Wait;

/// A CA and the bridge's and a forecaster's certificates, in a fresh directory.
fn pki() -> PathBuf {
    let dir = std::env::temp_dir().join(format!("upc-bench-pki-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/lab-pki.sh");
    for args in [vec!["ca"], vec!["issue", "bridge"], vec!["issue", "fc"]] {
        let ok = std::process::Command::new("bash")
            .arg(&script)
            .arg(args[0])
            .arg(&dir)
            .args(&args[1..])
            .output()
            .is_ok_and(|o| o.status.success());
        assert!(ok, "lab-pki {args:?}");
    }
    dir
}

fn bridge(c: &mut Criterion) {
    across(c, None);
    across(c, Some(&pki()));
}

/// Round trips through a bridge in this process: plain TCP, or mutual TLS with `pki`'s CA.
fn across(c: &mut Criterion, pki: Option<&Path>) {
    let label = if pki.is_some() { "tls" } else { "tcp" };
    let prefix = format!("bench_bridge_{label}_{}", std::process::id());
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("port")
        .port();
    let endpoint = format!("{label}/127.0.0.1:{port}");
    let pem = |f: &str| pki.map(|d| d.join(f).display().to_string());
    let mut sets = vec![
        format!("bridge.prefix=\"{prefix}\""),
        format!("bridge.key_prefix=\"{prefix}\""),
        format!("bridge.listen=[\"{endpoint}\"]"),
        // Round trips back to back are far above a forecaster's rate: no limit here.
        "bridge.forecast_rate_hz=1e9".into(),
        "bridge.forecast_burst=1000000".into(),
    ];
    if pki.is_some() {
        for (k, f) in [
            ("ca", "ca.pem"),
            ("certificate", "bridge.pem"),
            ("private_key", "bridge.key"),
        ] {
            sets.push(format!(
                "bridge.security.{k}={:?}",
                pem(f).unwrap_or_default()
            ));
        }
        sets.push("bridge.security.tls=true".into());
        sets.push("bridge.security.forecasters=[\"fc\"]".into());
    }
    let cfg = BridgeConfig::load(&[], &sets).expect("config");
    let stop = Arc::new(AtomicBool::new(false));
    let thread = {
        let stop = Arc::clone(&stop);
        std::thread::spawn(move || upc::bridge::run(&cfg, stop))
    };
    let node = ContractNode::open(&prefix, "bench-controller").expect("contract node");
    let forecasts = node.subscriber::<ForecastMsg>().expect("subscriber");
    let wake = node.listener(ServiceKind::Forecast).expect("listener");
    let mut zc = zenoh::Config::default();
    zc.insert_json5("connect/endpoints", &format!("[\"{endpoint}\"]"))
        .expect("config");
    zc.insert_json5("scouting/multicast/enabled", "false")
        .expect("config");
    let tls = "transport/link/tls";
    for (k, f) in [
        ("root_ca_certificate", "ca.pem"),
        ("connect_certificate", "fc.pem"),
        ("connect_private_key", "fc.key"),
    ] {
        if let Some(path) = pem(f) {
            zc.insert_json5(&format!("{tls}/{k}"), &format!("{path:?}"))
                .expect("config");
        }
    }
    if pki.is_some() {
        zc.insert_json5(&format!("{tls}/enable_mtls"), "true")
            .expect("config");
    }
    let session = zenoh::open(zc).wait().expect("zenoh");
    let publisher = session
        .declare_publisher(format!("{prefix}/forecast/fc"))
        .wait()
        .expect("publisher");
    let mut msg = Box::<ForecastMsg>::default();
    (msg.dt, msg.len) = (0.005, 500);
    let mut buf = Vec::new();
    let mut seq = 0u64;
    // One forecast across: put, then wait until the controller's side holds it (None: not
    // within `timeout`).
    let mut round_trip = |timeout: Duration| {
        seq += 1;
        msg.seq = seq;
        encode(msg.as_ref(), &mut buf);
        let start = Instant::now();
        publisher.put(buf.clone()).wait().expect("put");
        loop {
            if let Ok(Some(m)) = forecasts.latest()
                && m.seq == seq
            {
                return Some(start.elapsed());
            }
            if start.elapsed() > timeout {
                return None;
            }
            let _ = wake.wait(Duration::from_millis(1));
        }
    };
    // The first puts are lost until Zenoh has connected and declared.
    let connecting = Instant::now();
    while round_trip(Duration::from_millis(200)).is_none() {
        assert!(
            connecting.elapsed() < Duration::from_secs(30),
            "the bridge never delivered"
        );
    }
    let mut cross = || round_trip(Duration::from_secs(5)).expect("a forecast did not cross");
    let mut v: Vec<f64> = (0..2000).map(|_| cross().as_secs_f64() * 1e6).collect();
    v.sort_by(f64::total_cmp);
    println!(
        "bridge forecast latency ({label}) over 2000 round trips: p50 {:.0} µs, p99 {:.0} µs, max {:.0} µs",
        v[1000], v[1980], v[1999]
    );
    c.bench_function(&format!("bridge/forecast_zenoh_to_iceoryx2_{label}"), |b| {
        b.iter_custom(|iters| (0..iters).map(|_| cross()).sum())
    });
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let summary = thread.join().expect("bridge thread").expect("bridge");
    println!(
        "bridge ({label}, {}): {} forwarded, {} over the rate, forward p50 {:.0} µs p99 {:.0} µs (callback → iceoryx2)",
        summary.security,
        summary.forecasts_forwarded,
        summary.forecasts_rate_limited,
        summary.forward_p50_us,
        summary.forward_p99_us
    );
}

criterion_group!(benches, bridge);
criterion_main!(benches);
