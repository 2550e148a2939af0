//! The contract's payloads on Zenoh: a 16-byte header, then the `#[repr(C)]` bytes of the
//! message exactly as on iceoryx2 (services/CHANNELS.md, "Over Zenoh").
//!
//! iceoryx2 refuses a peer whose type name or size differs when it opens a service; Zenoh
//! carries bytes and checks nothing, so the header does it: a peer with another contract
//! version, or a payload of the wrong kind or size, is refused with the reason.

use crate::channels::{
    ForecastMsg, GroundTruthMsg, MAX_DOF, Payload, ServiceKind, StateMsg, TorqueMsg,
};

/// First bytes of every upc payload on Zenoh.
pub const WIRE_MAGIC: [u8; 4] = *b"UPCZ";
/// Version of the contract's payload layouts ([`crate::channels::CONTRACT_VERSION`]): peers of
/// another version are refused.
pub const WIRE_VERSION: u16 = crate::channels::CONTRACT_VERSION;
/// Header length (bytes): magic, version (u16), kind (u16), payload size (u32), reserved (u32).
pub const HEADER_LEN: usize = 16;

/// Why a payload from Zenoh was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    #[error("not a upc payload ({0} bytes without the UPCZ magic)")]
    NotUpc(usize),
    #[error(
        "the peer speaks contract version {peer}, this process version {ours}: run every \
         participant from the same upc version (services/CHANNELS.md, \"Contract version\")"
    )]
    Version { peer: u16, ours: u16 },
    #[error("a {got} payload on the {want} key")]
    Kind {
        got: &'static str,
        want: &'static str,
    },
    #[error("{kind} of {got} bytes, expected {want}")]
    Size {
        kind: &'static str,
        got: usize,
        want: usize,
    },
}

impl WireError {
    /// Short name for counters (`refused_by` in the bridge's summary).
    pub fn key(&self) -> &'static str {
        match self {
            WireError::NotUpc(_) => "not_upc",
            WireError::Version { .. } => "version",
            WireError::Kind { .. } => "kind",
            WireError::Size { .. } => "size",
        }
    }
}

/// A payload of the contract that crosses Zenoh.
///
/// # Safety
/// The type is `#[repr(C)]` plain old data of integers and floats with no implicit padding
/// (explicit `_pad` fields), so that its bytes are all initialised and any bytes are a value.
pub unsafe trait WireMessage: Payload + Default {}

// SAFETY: the four payloads are `#[repr(C)]`, made of u8/u32/u64/f64 fields and arrays, with
// explicit padding fields (their sizes are multiples of 8 and checked below).
unsafe impl WireMessage for StateMsg {}
unsafe impl WireMessage for TorqueMsg {}
unsafe impl WireMessage for ForecastMsg {}
unsafe impl WireMessage for GroundTruthMsg {}
// Each size is the sum of the fields' sizes (in 8-byte words): no byte of padding.
const _: () = assert!(size_of::<StateMsg>() == 8 * (7 + 3 * MAX_DOF + 24 + 7 + 2 + 16 + 26));
const _: () = assert!(size_of::<TorqueMsg>() == 8 * (6 + MAX_DOF));
const _: () = assert!(size_of::<ForecastMsg>() == 8 * (6 + 3 * crate::channels::MAX_FORECAST));
const _: () = assert!(size_of::<GroundTruthMsg>() == 8 * 14);
// The contract is little-endian; a big-endian host would need byte swaps the bridge lacks.
#[cfg(target_endian = "big")]
compile_error!("upc's channel contract is little-endian");

/// The kind's code in the header.
fn code(kind: ServiceKind) -> u16 {
    match kind {
        ServiceKind::State => 1,
        ServiceKind::Torques => 2,
        ServiceKind::Forecast => 3,
        ServiceKind::GroundTruth => 4,
    }
}

fn kind_name(code: u16) -> &'static str {
    match code {
        1 => "state",
        2 => "torques",
        3 => "forecast",
        4 => "ground_truth",
        _ => "unknown",
    }
}

/// The bytes of `msg` on Zenoh, written into `out` (cleared first; its capacity is reused).
pub fn encode<T: WireMessage>(msg: &T, out: &mut Vec<u8>) {
    let size = size_of::<T>();
    out.clear();
    out.extend_from_slice(&WIRE_MAGIC);
    out.extend_from_slice(&WIRE_VERSION.to_le_bytes());
    out.extend_from_slice(&code(T::KIND).to_le_bytes());
    out.extend_from_slice(&(size as u32).to_le_bytes());
    out.extend_from_slice(&0u32.to_le_bytes());
    // SAFETY: `WireMessage` types have no uninitialised (padding) bytes.
    let bytes = unsafe { std::slice::from_raw_parts((msg as *const T).cast::<u8>(), size) };
    out.extend_from_slice(bytes);
}

/// Check a payload from Zenoh and copy its message into `out`.
pub fn decode_into<T: WireMessage>(bytes: &[u8], out: &mut T) -> Result<(), WireError> {
    if bytes.len() < HEADER_LEN || bytes[..4] != WIRE_MAGIC {
        return Err(WireError::NotUpc(bytes.len()));
    }
    let u16_at = |i: usize| u16::from_le_bytes([bytes[i], bytes[i + 1]]);
    let version = u16_at(4);
    if version != WIRE_VERSION {
        return Err(WireError::Version {
            peer: version,
            ours: WIRE_VERSION,
        });
    }
    let kind = u16_at(6);
    if kind != code(T::KIND) {
        return Err(WireError::Kind {
            got: kind_name(kind),
            want: T::KIND.suffix(),
        });
    }
    let size = size_of::<T>();
    let declared = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize;
    let body = &bytes[HEADER_LEN..];
    if declared != size || body.len() != size {
        return Err(WireError::Size {
            kind: T::KIND.suffix(),
            got: body.len(),
            want: size,
        });
    }
    // SAFETY: `out` is a `WireMessage` of exactly `size` bytes, for which any bytes are a value.
    unsafe {
        std::ptr::copy_nonoverlapping(body.as_ptr(), (out as *mut T).cast::<u8>(), size);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_forecast_crosses_the_wire_unchanged() {
        let mut msg = ForecastMsg {
            seq: 7,
            t0: 1.25,
            dt: 0.005,
            len: 500,
            period: 0.01,
            scenario_hash: 0xdead_beef,
            ..Default::default()
        };
        msg.forces[3] = [-60.0, 6.0, -5.0];
        msg.forces[2047] = [f64::MIN_POSITIVE, -0.0, 1e300];
        let mut buf = Vec::new();
        encode(&msg, &mut buf);
        assert_eq!(buf.len(), HEADER_LEN + size_of::<ForecastMsg>());
        let mut back = ForecastMsg::default();
        decode_into(&buf, &mut back).unwrap();
        assert_eq!(
            (back.seq, back.len, back.scenario_hash),
            (7, 500, 0xdead_beef)
        );
        assert_eq!(back.t0.to_bits(), msg.t0.to_bits());
        for (a, b) in back.forces.iter().zip(&msg.forces) {
            for c in 0..3 {
                assert_eq!(a[c].to_bits(), b[c].to_bits());
            }
        }
    }

    #[test]
    fn wrong_magic_version_kind_and_size_are_refused_by_name() {
        let mut buf = Vec::new();
        encode(&StateMsg::default(), &mut buf);
        let mut f = ForecastMsg::default();
        let e = decode_into(&buf, &mut f).unwrap_err();
        assert_eq!(
            e,
            WireError::Kind {
                got: "state",
                want: "forecast"
            }
        );
        assert!(e.to_string().contains("state payload on the forecast key"));

        encode(&ForecastMsg::default(), &mut buf);
        let mut old = buf.clone();
        old[4] = 1;
        let e = decode_into(&old, &mut f).unwrap_err();
        assert_eq!(
            e,
            WireError::Version {
                peer: 1,
                ours: WIRE_VERSION
            }
        );
        assert!(e.to_string().contains("same upc version"), "{e}");
        let short = &buf[..buf.len() - 8];
        assert_eq!(decode_into(short, &mut f).unwrap_err().key(), "size");
        assert_eq!(decode_into(b"hello", &mut f), Err(WireError::NotUpc(5)));
        let mut garbage = buf.clone();
        garbage[0] = b'X';
        assert_eq!(decode_into(&garbage, &mut f).unwrap_err().key(), "not_upc");
        decode_into(&buf, &mut f).unwrap();
    }
}
