//! upc's Unitree G1 wire format (`upc::bus::unitree_hg`) against `scripts/unitree_crc.py`, an
//! implementation that shares no code with it: the same messages must give the same C-struct
//! image, CRC and CDR bytes, and upc must decode the script's bytes back to the message.
//!
//! Python 3 is required: without it these tests fail (they do not skip).

use std::io::Write;
use std::process::{Command, Stdio};

use serde_json::{Value, json};
use upc::bus::unitree_hg::{
    CDR_LE, ImuState, LOW_CMD_CDR_SIZE, LOW_CMD_IMAGE_SIZE, LOW_STATE_CDR_SIZE,
    LOW_STATE_IMAGE_SIZE, LowCmd, LowState, MOTOR_SLOTS, MotorCmd, MotorState,
};

const SCRIPT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/unitree_crc.py");

/// The script's answer for `doc` (passed on stdin, or as the argument with `args`).
fn python(doc: &Value, args: &[&str]) -> Value {
    let via_argv = !args.is_empty();
    let mut cmd = Command::new("python3");
    cmd.arg(SCRIPT).args(args);
    if via_argv {
        cmd.arg(doc.to_string());
    }
    let mut child = cmd
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| {
            panic!(
                "cannot run `python3` ({e}): this test checks upc's Unitree wire format against \
                 scripts/unitree_crc.py and needs Python 3 (standard library only) on PATH"
            )
        });
    let mut stdin = child.stdin.take().unwrap();
    if !via_argv {
        stdin.write_all(doc.to_string().as_bytes()).unwrap();
    }
    drop(stdin);
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "scripts/unitree_crc.py failed ({}): {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "scripts/unitree_crc.py printed no JSON ({e}): {}",
            String::from_utf8_lossy(&out.stdout)
        )
    })
}

/// f32 → JSON through f64: the decimal is then exact, so Python's double rounds back to the same
/// f32 bits.
fn f(x: f32) -> Value {
    json!(f64::from(x))
}

fn fs(xs: &[f32]) -> Value {
    Value::Array(xs.iter().map(|&x| f(x)).collect())
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn unhex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
        .collect()
}

fn cmd_json(m: &LowCmd) -> Value {
    let slots: Vec<Value> = m
        .motor_cmd
        .iter()
        .map(|c| {
            json!({
                "mode": c.mode, "q": f(c.q), "dq": f(c.dq), "tau": f(c.tau),
                "kp": f(c.kp), "kd": f(c.kd), "reserve": c.reserve,
            })
        })
        .collect();
    json!({
        "type": "LowCmd_",
        "mode_pr": m.mode_pr,
        "mode_machine": m.mode_machine,
        "motor_cmd": slots,
        "reserve": m.reserve,
        "crc": m.crc,
    })
}

fn state_json(m: &LowState) -> Value {
    let imu = &m.imu_state;
    let slots: Vec<Value> = m
        .motor_state
        .iter()
        .map(|s| {
            json!({
                "mode": s.mode, "q": f(s.q), "dq": f(s.dq), "ddq": f(s.ddq),
                "tau_est": f(s.tau_est), "temperature": s.temperature, "vol": f(s.vol),
                "sensor": s.sensor, "motorstate": s.motorstate, "reserve": s.reserve,
            })
        })
        .collect();
    json!({
        "type": "LowState_",
        "version": m.version,
        "mode_pr": m.mode_pr,
        "mode_machine": m.mode_machine,
        "tick": m.tick,
        "imu_state": {
            "quaternion": fs(&imu.quaternion),
            "gyroscope": fs(&imu.gyroscope),
            "accelerometer": fs(&imu.accelerometer),
            "rpy": fs(&imu.rpy),
            "temperature": imu.temperature,
        },
        "motor_state": slots,
        "wireless_remote": m.wireless_remote.to_vec(),
        "reserve": m.reserve,
        "crc": m.crc,
    })
}

fn check_cmd(m: &LowCmd) {
    let py = python(&cmd_json(m), &[]);
    assert_eq!(py["image_size"], LOW_CMD_IMAGE_SIZE);
    assert_eq!(py["image_hex"], hex(&m.struct_image()), "C-struct image");
    assert_eq!(py["crc"], m.compute_crc(), "CRC");
    let mut cdr = Vec::new();
    m.encode_cdr(&mut cdr);
    assert_eq!(py["cdr_size"], LOW_CMD_CDR_SIZE);
    assert_eq!(py["cdr_hex"], hex(&cdr), "CDR sample");
    let theirs = unhex(py["cdr_hex"].as_str().unwrap());
    assert_eq!(&LowCmd::decode_cdr(&theirs).unwrap(), m);
}

fn check_state(m: &LowState) {
    let py = python(&state_json(m), &[]);
    assert_eq!(py["image_size"], LOW_STATE_IMAGE_SIZE);
    assert_eq!(py["image_hex"], hex(&m.struct_image()), "C-struct image");
    assert_eq!(py["crc"], m.compute_crc(), "CRC");
    let mut cdr = Vec::new();
    m.encode_cdr(&mut cdr);
    assert_eq!(py["cdr_size"], LOW_STATE_CDR_SIZE);
    assert_eq!(py["cdr_hex"], hex(&cdr), "CDR sample");
    let theirs = unhex(py["cdr_hex"].as_str().unwrap());
    assert_eq!(&LowState::decode_cdr(&theirs).unwrap(), m);
}

/// A command as upc will send one: 29 joints enabled, each with its own targets and gains.
fn walking_cmd() -> LowCmd {
    let mut m = LowCmd {
        mode_pr: 1,
        mode_machine: 5,
        reserve: [1, 2, 3, 0xFFFF_FFFF],
        ..LowCmd::default()
    };
    for (i, c) in m.motor_cmd.iter_mut().enumerate() {
        let x = i as f32;
        *c = MotorCmd {
            mode: u8::from(i < 29),
            q: 0.1 * x - 1.2,
            dq: -0.013 * x,
            tau: 0.5 * x - 3.25,
            kp: 100.0 + 3.0 * x,
            kd: 2.0 + 0.25 * x,
            reserve: 0x0101_0101 * i as u32,
        };
    }
    m.seal();
    m
}

fn robot_state() -> LowState {
    let mut m = LowState {
        version: [3, 7],
        mode_pr: 1,
        mode_machine: 5,
        tick: 123_456_789,
        imu_state: ImuState {
            quaternion: [0.995, 0.01, -0.02, 0.0998],
            gyroscope: [0.12, -0.03, 0.4],
            accelerometer: [0.1, -0.2, 9.81],
            rpy: [0.02, -0.04, 0.2],
            temperature: 41,
        },
        reserve: [9, 8, 7, 6],
        ..LowState::default()
    };
    for (i, s) in m.motor_state.iter_mut().enumerate() {
        let x = i as f32;
        *s = MotorState {
            mode: 1 + (i % 3) as u8,
            q: 0.05 * x - 0.8,
            dq: 0.3 - 0.02 * x,
            ddq: 1.5 * x,
            tau_est: -2.0 + 0.4 * x,
            temperature: [30 + i as i16, -(i as i16)],
            vol: 48.5 - 0.1 * x,
            sensor: [i as u32, 0xABCD_0000 + i as u32],
            motorstate: 1 << (i % 32),
            reserve: [i as u32, 2 * i as u32, 3 * i as u32, 0xFFFF_FFFF - i as u32],
        };
    }
    for (i, b) in m.wireless_remote.iter_mut().enumerate() {
        *b = (i * 7 + 0x55) as u8;
    }
    m.seal();
    m
}

#[test]
fn a_walking_command_matches_the_independent_implementation() {
    let m = walking_cmd();
    assert!(m.crc_ok());
    check_cmd(&m);
}

#[test]
fn an_all_zero_command_and_the_script_sealing_it() {
    check_cmd(&LowCmd::default());
    // The script's --seal, the JSON as its argument: the same bytes as upc's sealed command.
    let mut sealed = LowCmd::default();
    sealed.seal();
    let py = python(&cmd_json(&LowCmd::default()), &["--seal"]);
    let mut cdr = Vec::new();
    sealed.encode_cdr(&mut cdr);
    assert_eq!(py["crc"], sealed.crc);
    assert_eq!(py["cdr_hex"], hex(&cdr));
    assert_eq!(cdr[..4], CDR_LE);
}

#[test]
fn a_command_with_extreme_values_and_a_stale_crc() {
    let mut m = walking_cmd();
    m.mode_pr = 0xFF;
    m.mode_machine = 0x80;
    m.motor_cmd[0].q = -0.0;
    m.motor_cmd[1].q = f32::from_bits(1); // smallest subnormal
    m.motor_cmd[2].kp = f32::MAX;
    m.motor_cmd[3].kd = f32::MIN_POSITIVE;
    m.motor_cmd[MOTOR_SLOTS - 1].mode = 0xFF;
    m.motor_cmd[MOTOR_SLOTS - 1].reserve = u32::MAX;
    m.crc = 0x1234_5678; // not the CRC: the script must compute, not echo
    assert!(!m.crc_ok());
    check_cmd(&m);
}

#[test]
fn a_robot_state_matches_the_independent_implementation() {
    let m = robot_state();
    assert!(m.crc_ok());
    check_state(&m);
}

#[test]
fn a_state_with_extreme_values() {
    let mut m = robot_state();
    m.version = [u32::MAX, 0];
    m.tick = u32::MAX;
    m.imu_state.temperature = i16::MIN;
    m.imu_state.rpy = [-0.0, f32::MIN, f32::from_bits(0x0000_0401)];
    m.motor_state[0].temperature = [i16::MIN, i16::MAX];
    m.motor_state[MOTOR_SLOTS - 1].mode = 0xFF;
    m.wireless_remote = [0xFF; 40];
    m.seal();
    check_state(&m);
    check_state(&LowState::default());
}
