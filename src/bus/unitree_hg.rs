//! The G1's low-level messages (`unitree_hg` in Unitree's unitree_sdk2 IDL): `LowState_` from the
//! robot on `rt/lowstate`, `LowCmd_` to it on `rt/lowcmd`.
//!
//! Each message has two byte layouts:
//! - on the wire, XCDR1 little endian ([`CDR_LE`] header, then each primitive aligned to its own
//!   size from the start of the payload, no struct padding): [`LowCmd::encode_cdr`],
//!   [`LowState::decode_cdr`], …;
//! - for the CRC, the little-endian image of the equivalent C struct (natural alignment, nested
//!   structs padded to 4 at both ends), which is what Unitree's firmware and SDK checksum:
//!   [`LowCmd::struct_image`]. The robot drops a command whose `crc` does not match it, so a
//!   command is [`LowCmd::seal`]ed after its last change.
//!
//! One field walk per message (`put`) feeds both layouts through a `Sink`, so they cannot disagree
//! on field order. Nothing here allocates except the caller's output `Vec`, and no input makes
//! the decoders panic: the length is checked first, and the reader reads zeros past the end.

/// Joint slots in every message (the G1 uses 29 of them; the rest stay zero).
pub const MOTOR_SLOTS: usize = 35;
/// Topic of [`LowState`] (robot → upc).
pub const LOW_STATE_TOPIC: &str = "rt/lowstate";
/// Topic of [`LowCmd`] (upc → robot).
pub const LOW_CMD_TOPIC: &str = "rt/lowcmd";
/// DDS type name of [`LowState`]: readers and writers only match on equal type names.
pub const LOW_STATE_TYPE_NAME: &str = "unitree_hg::msg::dds_::LowState_";
/// DDS type name of [`LowCmd`].
pub const LOW_CMD_TYPE_NAME: &str = "unitree_hg::msg::dds_::LowCmd_";
/// `sizeof(LowCmd_)` in C: the bytes the CRC is computed over (with the crc word last).
pub const LOW_CMD_IMAGE_SIZE: usize = 1004;
/// `sizeof(LowState_)` in C.
pub const LOW_STATE_IMAGE_SIZE: usize = 2092;
/// Encapsulation header of a sample: CDR_LE (XCDR1, little endian), options zero.
pub const CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];
/// Serialized `LowCmd_` on the wire, header included (equal to the image size by coincidence:
/// CDR drops the image's 4 padding bytes and adds the 4-byte header).
pub const LOW_CMD_CDR_SIZE: usize = 1004;
/// Serialized `LowState_` on the wire, header included.
pub const LOW_STATE_CDR_SIZE: usize = 2092;
/// Unitree's CRC-32 (CRC-32/MPEG-2: MSB first, no reflection, no final XOR).
pub const CRC_POLY: u32 = 0x04C1_1DB7;
/// Initial register value of the CRC.
pub const CRC_INIT: u32 = 0xFFFF_FFFF;

/// Alignment of every nested C struct here: their widest member is 4 bytes (f32/u32).
const C_STRUCT_ALIGN: usize = 4;

/// Why bytes from the bus are not a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    #[error("{got} bytes: too short for the 4-byte CDR encapsulation header")]
    TooShort { got: usize },
    #[error(
        "encapsulation {id:02x?} is not CDR_LE [00, 01] (XCDR1 little endian, what Unitree's \
         firmware sends)"
    )]
    BadEncapsulation { id: [u8; 2] },
    #[error("{type_name}: {got} bytes after the header, {want} expected (truncated sample)")]
    Truncated {
        type_name: &'static str,
        got: usize,
        want: usize,
    },
    #[error("{type_name}: {got} bytes that do not decode as this type")]
    Malformed { type_name: &'static str, got: usize },
    #[error("{type_name}: {extra} extra bytes after the sample (another type or layout version?)")]
    Trailing {
        type_name: &'static str,
        extra: usize,
    },
}

/// IMU readings in `LowState_` (torso IMU).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ImuState {
    /// Orientation, w x y z.
    pub quaternion: [f32; 4],
    /// Angular velocity (rad/s).
    pub gyroscope: [f32; 3],
    /// Specific force (m/s²).
    pub accelerometer: [f32; 3],
    /// Roll, pitch, yaw (rad).
    pub rpy: [f32; 3],
    pub temperature: i16,
}

/// One joint's drive as reported in `LowState_`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct MotorState {
    pub mode: u8,
    /// Joint position (rad).
    pub q: f32,
    /// Joint velocity (rad/s).
    pub dq: f32,
    pub ddq: f32,
    /// Estimated joint torque (N m).
    pub tau_est: f32,
    pub temperature: [i16; 2],
    /// Supply voltage (V).
    pub vol: f32,
    pub sensor: [u32; 2],
    /// Fault and status bits of the drive.
    pub motorstate: u32,
    pub reserve: [u32; 4],
}

/// One joint's target in `LowCmd_`. The drive applies
/// τ = tau + kp (q − q_meas) + kd (dq − dq_meas).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct MotorCmd {
    /// 1 enables the drive, 0 lets the joint go limp.
    pub mode: u8,
    pub q: f32,
    pub dq: f32,
    /// Feedforward torque (N m).
    pub tau: f32,
    pub kp: f32,
    pub kd: f32,
    pub reserve: u32,
}

/// `unitree_hg::msg::dds_::LowState_`, published by the robot.
#[derive(Debug, Clone, PartialEq)]
pub struct LowState {
    pub version: [u32; 2],
    pub mode_pr: u8,
    pub mode_machine: u8,
    pub tick: u32,
    pub imu_state: ImuState,
    pub motor_state: [MotorState; MOTOR_SLOTS],
    pub wireless_remote: [u8; 40],
    pub reserve: [u32; 4],
    pub crc: u32,
}

/// `unitree_hg::msg::dds_::LowCmd_`, published by the controller.
#[derive(Debug, Clone, PartialEq)]
pub struct LowCmd {
    pub mode_pr: u8,
    pub mode_machine: u8,
    pub motor_cmd: [MotorCmd; MOTOR_SLOTS],
    pub reserve: [u32; 4],
    pub crc: u32,
}

// `Default` is derived for arrays of at most 32 elements only.
impl Default for LowState {
    fn default() -> Self {
        Self {
            version: [0; 2],
            mode_pr: 0,
            mode_machine: 0,
            tick: 0,
            imu_state: ImuState::default(),
            motor_state: [MotorState::default(); MOTOR_SLOTS],
            wireless_remote: [0; 40],
            reserve: [0; 4],
            crc: 0,
        }
    }
}

impl Default for LowCmd {
    fn default() -> Self {
        Self {
            mode_pr: 0,
            mode_machine: 0,
            motor_cmd: [MotorCmd::default(); MOTOR_SLOTS],
            reserve: [0; 4],
            crc: 0,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// CRC

/// Byte-at-a-time table of the MSB-first CRC, built at compile time.
const CRC_TABLE: [u32; 256] = {
    let mut table = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = (i as u32) << 24;
        let mut bit = 0;
        while bit < 8 {
            c = if c & 0x8000_0000 != 0 {
                (c << 1) ^ CRC_POLY
            } else {
                c << 1
            };
            bit += 1;
        }
        table[i] = c;
        i += 1;
    }
    table
};

/// Feed one byte, MSB first.
fn crc_byte(crc: u32, byte: u8) -> u32 {
    (crc << 8) ^ CRC_TABLE[usize::from((crc >> 24) as u8 ^ byte)]
}

/// Feed one word from bit 31 down to bit 0 (as Unitree's `crc32_core`): its big-endian bytes.
fn crc_word(crc: u32, word: u32) -> u32 {
    word.to_be_bytes().into_iter().fold(crc, crc_byte)
}

/// Unitree's CRC-32 of a sequence of words (CRC-32/MPEG-2 of their big-endian bytes).
pub fn crc32_words(words: &[u32]) -> u32 {
    words.iter().fold(CRC_INIT, |crc, &w| crc_word(crc, w))
}

/// The CRC of a C-struct image: its little-endian words, all but the last (the crc itself).
fn crc_of_image(image: &[u8]) -> u32 {
    let words = (image.len() / 4).saturating_sub(1);
    image.chunks_exact(4).take(words).fold(CRC_INIT, |crc, w| {
        crc_word(crc, u32::from_le_bytes([w[0], w[1], w[2], w[3]]))
    })
}

// ---------------------------------------------------------------------------------------------
// Layouts

/// Where a message's fields go, in IDL order: the CDR stream or the C-struct image.
trait Sink {
    /// Write a primitive's little-endian bytes, aligned to its size.
    fn put<const N: usize>(&mut self, le: [u8; N]);
    /// A nested struct begins or ends: C pads to the struct's alignment, CDR does not.
    fn struct_edge(&mut self);

    fn u8(&mut self, v: u8) {
        self.put(v.to_le_bytes());
    }
    fn i16(&mut self, v: i16) {
        self.put(v.to_le_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.put(v.to_le_bytes());
    }
    fn f32(&mut self, v: f32) {
        self.put(v.to_le_bytes());
    }
}

fn align_up(pos: usize, align: usize) -> usize {
    pos.next_multiple_of(align)
}

/// XCDR1 body: alignment counts from the first byte after the encapsulation header.
struct CdrWriter<'a> {
    out: &'a mut Vec<u8>,
    origin: usize,
}

impl Sink for CdrWriter<'_> {
    fn put<const N: usize>(&mut self, le: [u8; N]) {
        let at = self.out.len() - self.origin;
        self.out.resize(self.origin + align_up(at, N), 0);
        self.out.extend_from_slice(&le);
    }
    fn struct_edge(&mut self) {}
}

/// The C struct's bytes, padding zeroed (so the CRC does not depend on stack garbage, as
/// Unitree's code gets by zero-initialising its struct).
struct ImageWriter<const L: usize> {
    buf: [u8; L],
    pos: usize,
}

impl<const L: usize> ImageWriter<L> {
    fn new() -> Self {
        Self {
            buf: [0; L],
            pos: 0,
        }
    }
}

impl<const L: usize> Sink for ImageWriter<L> {
    fn put<const N: usize>(&mut self, le: [u8; N]) {
        self.pos = align_up(self.pos, N);
        // The walks fill exactly L bytes (tested); past the end would be a layout bug, not input.
        if let Some(dst) = self.buf.get_mut(self.pos..self.pos + N) {
            dst.copy_from_slice(&le);
        }
        self.pos += N;
    }
    fn struct_edge(&mut self) {
        self.pos = align_up(self.pos, C_STRUCT_ALIGN);
    }
}

/// Reads an XCDR1 body. Past the end it yields zeros and remembers it, so that no input panics.
struct CdrReader<'a> {
    buf: &'a [u8],
    pos: usize,
    short: bool,
}

impl<'a> CdrReader<'a> {
    fn new(buf: &'a [u8]) -> Self {
        Self {
            buf,
            pos: 0,
            short: false,
        }
    }

    fn take<const N: usize>(&mut self) -> [u8; N] {
        self.pos = align_up(self.pos, N);
        let bytes = self
            .buf
            .get(self.pos..self.pos + N)
            .and_then(|s| <[u8; N]>::try_from(s).ok());
        self.pos += N;
        bytes.unwrap_or_else(|| {
            self.short = true;
            [0; N]
        })
    }
    fn u8(&mut self) -> u8 {
        u8::from_le_bytes(self.take())
    }
    fn i16(&mut self) -> i16 {
        i16::from_le_bytes(self.take())
    }
    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take())
    }
    fn f32(&mut self) -> f32 {
        f32::from_le_bytes(self.take())
    }
    fn f32s<const N: usize>(&mut self) -> [f32; N] {
        let mut a = [0.0; N];
        for v in &mut a {
            *v = self.f32();
        }
        a
    }
    fn u32s<const N: usize>(&mut self) -> [u32; N] {
        let mut a = [0; N];
        for v in &mut a {
            *v = self.u32();
        }
        a
    }
}

/// Check the header and body length of a sample of `want` bytes (header included); the body.
fn cdr_body<'a>(
    bytes: &'a [u8],
    type_name: &'static str,
    want: usize,
) -> Result<&'a [u8], WireError> {
    let Some((header, body)) = bytes.split_first_chunk::<4>() else {
        return Err(WireError::TooShort { got: bytes.len() });
    };
    // The options (bytes 2–3) are ignored: both bodies are multiples of 4, so no end padding.
    if header[..2] != CDR_LE[..2] {
        return Err(WireError::BadEncapsulation {
            id: [header[0], header[1]],
        });
    }
    body_of_length(body, type_name, want - CDR_LE.len())
}

/// Check that a body (the bytes after the encapsulation header) has `want` bytes.
fn body_of_length<'a>(
    body: &'a [u8],
    type_name: &'static str,
    want: usize,
) -> Result<&'a [u8], WireError> {
    match body.len() {
        n if n < want => Err(WireError::Truncated {
            type_name,
            got: n,
            want,
        }),
        n if n > want => Err(WireError::Trailing {
            type_name,
            extra: n - want,
        }),
        _ => Ok(body),
    }
}

/// Start a sample in `out` (cleared; its capacity is kept, so a reused buffer does not allocate).
fn cdr_writer(out: &mut Vec<u8>, size: usize) -> CdrWriter<'_> {
    out.clear();
    out.reserve(size);
    out.extend_from_slice(&CDR_LE);
    let origin = out.len();
    CdrWriter { out, origin }
}

fn finish_read<T>(r: &CdrReader, value: T, type_name: &'static str) -> Result<T, WireError> {
    // Unreachable after `cdr_body`'s length check unless the walk and the size constant differ.
    if r.short || r.pos != r.buf.len() {
        return Err(WireError::Truncated {
            type_name,
            got: r.buf.len(),
            want: r.pos,
        });
    }
    Ok(value)
}

// ---------------------------------------------------------------------------------------------
// Field walks, in the IDL's order

impl ImuState {
    fn put<S: Sink>(&self, s: &mut S) {
        s.struct_edge();
        for &v in self
            .quaternion
            .iter()
            .chain(&self.gyroscope)
            .chain(&self.accelerometer)
            .chain(&self.rpy)
        {
            s.f32(v);
        }
        s.i16(self.temperature);
        s.struct_edge();
    }

    fn get(r: &mut CdrReader) -> Self {
        Self {
            quaternion: r.f32s(),
            gyroscope: r.f32s(),
            accelerometer: r.f32s(),
            rpy: r.f32s(),
            temperature: r.i16(),
        }
    }
}

impl MotorState {
    fn put<S: Sink>(&self, s: &mut S) {
        s.struct_edge();
        s.u8(self.mode);
        s.f32(self.q);
        s.f32(self.dq);
        s.f32(self.ddq);
        s.f32(self.tau_est);
        s.i16(self.temperature[0]);
        s.i16(self.temperature[1]);
        s.f32(self.vol);
        s.u32(self.sensor[0]);
        s.u32(self.sensor[1]);
        s.u32(self.motorstate);
        for &v in &self.reserve {
            s.u32(v);
        }
        s.struct_edge();
    }

    fn get(r: &mut CdrReader) -> Self {
        // Struct expressions evaluate their fields in the order written: the IDL's.
        Self {
            mode: r.u8(),
            q: r.f32(),
            dq: r.f32(),
            ddq: r.f32(),
            tau_est: r.f32(),
            temperature: [r.i16(), r.i16()],
            vol: r.f32(),
            sensor: r.u32s(),
            motorstate: r.u32(),
            reserve: r.u32s(),
        }
    }
}

impl MotorCmd {
    fn put<S: Sink>(&self, s: &mut S) {
        s.struct_edge();
        s.u8(self.mode);
        s.f32(self.q);
        s.f32(self.dq);
        s.f32(self.tau);
        s.f32(self.kp);
        s.f32(self.kd);
        s.u32(self.reserve);
        s.struct_edge();
    }

    fn get(r: &mut CdrReader) -> Self {
        Self {
            mode: r.u8(),
            q: r.f32(),
            dq: r.f32(),
            tau: r.f32(),
            kp: r.f32(),
            kd: r.f32(),
            reserve: r.u32(),
        }
    }
}

/// What both messages do with their one field walk (`put`): the C-struct image and its CRC, and
/// the wire encoding. A command is sealed as the last step before publishing (the robot ignores
/// one whose CRC does not match); a simulated robot seals its states.
macro_rules! sealed_message {
    ($msg:ident, $c_name:literal, $image_size:expr, $cdr_size:expr) => {
        impl $msg {
            fn image(&self) -> ImageWriter<$image_size> {
                let mut w = ImageWriter::new();
                self.put(&mut w);
                w
            }

            #[doc = concat!("The little-endian bytes of the C struct `", $c_name, "` (what the CRC covers).")]
            pub fn struct_image(&self) -> [u8; $image_size] {
                self.image().buf
            }

            /// The CRC the message should carry.
            pub fn compute_crc(&self) -> u32 {
                crc_of_image(&self.struct_image())
            }

            /// Set `crc` from the other fields.
            pub fn seal(&mut self) {
                self.crc = self.compute_crc();
            }

            /// Whether `crc` matches the other fields (a sample corrupted or from another
            /// layout fails).
            pub fn crc_ok(&self) -> bool {
                self.crc == self.compute_crc()
            }

            /// The sample on the wire, header included, into `out` (cleared first).
            pub fn encode_cdr(&self, out: &mut Vec<u8>) {
                self.put(&mut cdr_writer(out, $cdr_size));
            }
        }
    };
}

sealed_message!(
    LowState,
    "LowState_",
    LOW_STATE_IMAGE_SIZE,
    LOW_STATE_CDR_SIZE
);
sealed_message!(LowCmd, "LowCmd_", LOW_CMD_IMAGE_SIZE, LOW_CMD_CDR_SIZE);

impl LowState {
    fn put<S: Sink>(&self, s: &mut S) {
        s.struct_edge();
        s.u32(self.version[0]);
        s.u32(self.version[1]);
        s.u8(self.mode_pr);
        s.u8(self.mode_machine);
        s.u32(self.tick);
        self.imu_state.put(s);
        for m in &self.motor_state {
            m.put(s);
        }
        for &b in &self.wireless_remote {
            s.u8(b);
        }
        for &v in &self.reserve {
            s.u32(v);
        }
        s.u32(self.crc);
        s.struct_edge();
    }

    /// A sample from the wire. The CRC is not checked here: see [`LowState::crc_ok`].
    pub fn decode_cdr(bytes: &[u8]) -> Result<Self, WireError> {
        Self::decode_body(cdr_body(bytes, "LowState_", LOW_STATE_CDR_SIZE)?)
    }

    /// A sample's body, the bytes after the CDR_LE header (what a DDS library hands over).
    pub fn decode_body(body: &[u8]) -> Result<Self, WireError> {
        let body = body_of_length(body, "LowState_", LOW_STATE_CDR_SIZE - CDR_LE.len())?;
        let mut r = CdrReader::new(body);
        let version = r.u32s();
        let mode_pr = r.u8();
        let mode_machine = r.u8();
        let tick = r.u32();
        let imu_state = ImuState::get(&mut r);
        let mut motor_state = [MotorState::default(); MOTOR_SLOTS];
        for m in &mut motor_state {
            *m = MotorState::get(&mut r);
        }
        let mut wireless_remote = [0; 40];
        for b in &mut wireless_remote {
            *b = r.u8();
        }
        let reserve = r.u32s();
        let crc = r.u32();
        let msg = Self {
            version,
            mode_pr,
            mode_machine,
            tick,
            imu_state,
            motor_state,
            wireless_remote,
            reserve,
            crc,
        };
        finish_read(&r, msg, "LowState_")
    }
}

impl LowCmd {
    fn put<S: Sink>(&self, s: &mut S) {
        s.struct_edge();
        s.u8(self.mode_pr);
        s.u8(self.mode_machine);
        for m in &self.motor_cmd {
            m.put(s);
        }
        for &v in &self.reserve {
            s.u32(v);
        }
        s.u32(self.crc);
        s.struct_edge();
    }

    /// A sample from the wire. The CRC is not checked here: see [`LowCmd::crc_ok`].
    pub fn decode_cdr(bytes: &[u8]) -> Result<Self, WireError> {
        Self::decode_body(cdr_body(bytes, "LowCmd_", LOW_CMD_CDR_SIZE)?)
    }

    /// A sample's body, the bytes after the CDR_LE header (what a DDS library hands over).
    pub fn decode_body(body: &[u8]) -> Result<Self, WireError> {
        let body = body_of_length(body, "LowCmd_", LOW_CMD_CDR_SIZE - CDR_LE.len())?;
        let mut r = CdrReader::new(body);
        let mode_pr = r.u8();
        let mode_machine = r.u8();
        let mut motor_cmd = [MotorCmd::default(); MOTOR_SLOTS];
        for m in &mut motor_cmd {
            *m = MotorCmd::get(&mut r);
        }
        let msg = Self {
            mode_pr,
            mode_machine,
            motor_cmd,
            reserve: r.u32s(),
            crc: r.u32(),
        };
        finish_read(&r, msg, "LowCmd_")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// splitmix64: distinct, reproducible values for every field.
    struct Gen(u64);
    impl Gen {
        fn next(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^ (z >> 31)
        }
        fn u8(&mut self) -> u8 {
            self.next() as u8 | 1
        }
        fn i16(&mut self) -> i16 {
            self.next() as i16 | 1
        }
        fn u32(&mut self) -> u32 {
            self.next() as u32 | 1
        }
        /// A finite float in ±100 with 4 decimals (NaN would defeat `PartialEq`).
        fn f32(&mut self) -> f32 {
            (self.next() % 2_000_000) as f32 / 10_000.0 - 100.05
        }
    }

    fn sample_state(g: &mut Gen) -> LowState {
        let mut m = LowState {
            version: [g.u32(), g.u32()],
            mode_pr: g.u8(),
            mode_machine: g.u8(),
            tick: g.u32(),
            imu_state: ImuState {
                quaternion: [g.f32(), g.f32(), g.f32(), g.f32()],
                gyroscope: [g.f32(), g.f32(), g.f32()],
                accelerometer: [g.f32(), g.f32(), g.f32()],
                rpy: [g.f32(), g.f32(), g.f32()],
                temperature: g.i16(),
            },
            ..LowState::default()
        };
        for s in &mut m.motor_state {
            *s = MotorState {
                mode: g.u8(),
                q: g.f32(),
                dq: g.f32(),
                ddq: g.f32(),
                tau_est: g.f32(),
                temperature: [g.i16(), g.i16()],
                vol: g.f32(),
                sensor: [g.u32(), g.u32()],
                motorstate: g.u32(),
                reserve: [g.u32(), g.u32(), g.u32(), g.u32()],
            };
        }
        for b in &mut m.wireless_remote {
            *b = g.u8();
        }
        m.reserve = [g.u32(), g.u32(), g.u32(), g.u32()];
        m.crc = g.u32();
        m
    }

    fn sample_cmd(g: &mut Gen) -> LowCmd {
        let mut m = LowCmd {
            mode_pr: g.u8(),
            mode_machine: g.u8(),
            ..LowCmd::default()
        };
        for c in &mut m.motor_cmd {
            *c = MotorCmd {
                mode: g.u8(),
                q: g.f32(),
                dq: g.f32(),
                tau: g.f32(),
                kp: g.f32(),
                kd: g.f32(),
                reserve: g.u32(),
            };
        }
        m.reserve = [g.u32(), g.u32(), g.u32(), g.u32()];
        m.crc = g.u32();
        m
    }

    fn u32_at(b: &[u8], at: usize) -> u32 {
        u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
    }
    fn f32_at(b: &[u8], at: usize) -> f32 {
        f32::from_le_bytes(b[at..at + 4].try_into().unwrap())
    }
    fn i16_at(b: &[u8], at: usize) -> i16 {
        i16::from_le_bytes(b[at..at + 2].try_into().unwrap())
    }

    #[test]
    fn low_cmd_round_trips_through_cdr_at_the_offsets_worked_out_by_hand() {
        let m = sample_cmd(&mut Gen(1));
        let mut buf = vec![0xAA; 7]; // stale contents are replaced
        m.encode_cdr(&mut buf);
        assert_eq!(buf.len(), LOW_CMD_CDR_SIZE);
        assert_eq!(buf[..4], CDR_LE);
        // Offsets from the payload start: mode_pr 0, mode_machine 1, slot 0's mode at 2 and q at
        // 4 (no struct padding in CDR), then 28 bytes a slot; reserve at 980, crc at 996.
        let p = &buf[4..];
        assert_eq!(
            (p[0], p[1], p[2], p[3]),
            (m.mode_pr, m.mode_machine, m.motor_cmd[0].mode, 0)
        );
        assert_eq!(f32_at(p, 4), m.motor_cmd[0].q);
        assert_eq!(u32_at(p, 24), m.motor_cmd[0].reserve);
        assert_eq!(p[28], m.motor_cmd[1].mode);
        assert_eq!(f32_at(p, 28 * 34 + 20), m.motor_cmd[34].kd);
        assert_eq!(u32_at(p, 980), m.reserve[0]);
        assert_eq!(u32_at(p, 996), m.crc);

        let back = LowCmd::decode_cdr(&buf).unwrap();
        assert_eq!(back, m);
        let mut again = Vec::new();
        back.encode_cdr(&mut again);
        assert_eq!(again, buf);
    }

    #[test]
    fn low_state_round_trips_through_cdr_at_the_offsets_worked_out_by_hand() {
        let m = sample_state(&mut Gen(2));
        let mut buf = Vec::new();
        m.encode_cdr(&mut buf);
        assert_eq!(buf.len(), LOW_STATE_CDR_SIZE);
        assert_eq!(buf[..4], CDR_LE);
        // version 0..8, mode_pr 8, mode_machine 9, tick 12, IMU 16..70 (temperature at 68),
        // slot 0's mode at 70 and q at 72, slot k ≥ 1 at 124 + 56 (k − 1), wireless_remote at
        // 2028, reserve at 2068, crc at 2084.
        let p = &buf[4..];
        assert_eq!(u32_at(p, 4), m.version[1]);
        assert_eq!((p[8], p[9]), (m.mode_pr, m.mode_machine));
        assert_eq!(u32_at(p, 12), m.tick);
        assert_eq!(f32_at(p, 16), m.imu_state.quaternion[0]);
        assert_eq!(f32_at(p, 64), m.imu_state.rpy[2]);
        assert_eq!(i16_at(p, 68), m.imu_state.temperature);
        assert_eq!(p[70], m.motor_state[0].mode);
        assert_eq!(f32_at(p, 72), m.motor_state[0].q);
        assert_eq!(i16_at(p, 90), m.motor_state[0].temperature[1]);
        assert_eq!(u32_at(p, 120), m.motor_state[0].reserve[3]);
        assert_eq!(p[124], m.motor_state[1].mode);
        let last = 124 + 56 * 33;
        assert_eq!(f32_at(p, last + 4), m.motor_state[34].q);
        assert_eq!(p[2028], m.wireless_remote[0]);
        assert_eq!(p[2067], m.wireless_remote[39]);
        assert_eq!(u32_at(p, 2068), m.reserve[0]);
        assert_eq!(u32_at(p, 2084), m.crc);

        let back = LowState::decode_cdr(&buf).unwrap();
        assert_eq!(back, m);
        let mut again = Vec::new();
        back.encode_cdr(&mut again);
        assert_eq!(again, buf);
    }

    #[test]
    fn struct_images_have_the_c_sizes_and_offsets() {
        let cmd = sample_cmd(&mut Gen(3));
        let w = cmd.image();
        assert_eq!(w.pos, LOW_CMD_IMAGE_SIZE);
        assert_eq!(w.pos, 1004);
        let img = w.buf;
        // C: mode_pr, mode_machine, 2 padding bytes, then 35 MotorCmd_ of 28 bytes (mode at 0,
        // 3 padding bytes, q at 4), reserve at 984, crc at 1000.
        assert_eq!(
            (img[0], img[1], img[2], img[3]),
            (cmd.mode_pr, cmd.mode_machine, 0, 0)
        );
        assert_eq!(img[4], cmd.motor_cmd[0].mode);
        assert_eq!(img[5..8], [0, 0, 0]);
        assert_eq!(f32_at(&img, 8), cmd.motor_cmd[0].q);
        assert_eq!(img[4 + 28 * 34], cmd.motor_cmd[34].mode);
        assert_eq!(u32_at(&img, 984), cmd.reserve[0]);
        assert_eq!(u32_at(&img, 1000), cmd.crc);

        let st = sample_state(&mut Gen(4));
        let w = st.image();
        assert_eq!(w.pos, LOW_STATE_IMAGE_SIZE);
        assert_eq!(w.pos, 2092);
        let img = w.buf;
        // C: version 0, modes 8 and 9, tick 12, IMUState_ 16..72 (temperature at 68, 2 padding
        // bytes), 35 MotorState_ of 56 bytes from 72, wireless_remote 2032, reserve 2072, crc 2088.
        assert_eq!((img[10], img[11]), (0, 0));
        assert_eq!(u32_at(&img, 12), st.tick);
        assert_eq!(i16_at(&img, 68), st.imu_state.temperature);
        assert_eq!((img[70], img[71]), (0, 0));
        assert_eq!(img[72], st.motor_state[0].mode);
        assert_eq!(f32_at(&img, 76), st.motor_state[0].q);
        assert_eq!(img[72 + 56 * 34], st.motor_state[34].mode);
        assert_eq!(
            u32_at(&img, 72 + 56 * 35 - 4),
            st.motor_state[34].reserve[3]
        );
        assert_eq!(img[2032], st.wireless_remote[0]);
        assert_eq!(u32_at(&img, 2072), st.reserve[0]);
        assert_eq!(u32_at(&img, 2088), st.crc);
    }

    /// Unitree's `crc32_core` as published: shift, then XOR the polynomial for the top bit and
    /// again for the data bit.
    fn unitree_crc32_core(words: &[u32]) -> u32 {
        let mut crc = 0xFFFF_FFFFu32;
        for &data in words {
            let mut xbit = 1u32 << 31;
            for _ in 0..32 {
                if crc & 0x8000_0000 != 0 {
                    crc = (crc << 1) ^ CRC_POLY;
                } else {
                    crc <<= 1;
                }
                if data & xbit != 0 {
                    crc ^= CRC_POLY;
                }
                xbit >>= 1;
            }
        }
        crc
    }

    #[test]
    fn the_crc_is_unitrees_crc32_core_and_crc32_mpeg2() {
        // The catalogued check value of CRC-32/MPEG-2.
        assert_eq!(
            b"123456789".iter().fold(CRC_INIT, |c, &b| crc_byte(c, b)),
            0x0376_E6E7
        );
        let mut g = Gen(5);
        let words: Vec<u32> = (0..300).map(|_| g.next() as u32).collect();
        for n in [0, 1, 2, 7, 250, 300] {
            assert_eq!(
                crc32_words(&words[..n]),
                unitree_crc32_core(&words[..n]),
                "{n} words"
            );
        }
        let cmd = sample_cmd(&mut Gen(6));
        let img = cmd.struct_image();
        let img_words: Vec<u32> = img
            .chunks_exact(4)
            .map(|w| u32::from_le_bytes(w.try_into().unwrap()))
            .collect();
        assert_eq!(img_words.len(), LOW_CMD_IMAGE_SIZE / 4);
        assert_eq!(
            cmd.compute_crc(),
            unitree_crc32_core(&img_words[..img_words.len() - 1])
        );
    }

    /// Change field number `k` of a command (IDL order, arrays element by element); false past
    /// the last field. The crc field is left out: it is not covered by the CRC.
    fn poke_cmd(m: &mut LowCmd, k: usize) -> bool {
        match k {
            0 => m.mode_pr ^= 1,
            1 => m.mode_machine ^= 1,
            k if k < 2 + 7 * MOTOR_SLOTS => {
                let c = &mut m.motor_cmd[(k - 2) / 7];
                match (k - 2) % 7 {
                    0 => c.mode ^= 1,
                    1 => c.q += 1.0,
                    2 => c.dq += 1.0,
                    3 => c.tau += 1.0,
                    4 => c.kp += 1.0,
                    5 => c.kd += 1.0,
                    _ => c.reserve ^= 1,
                }
            }
            k if k < 2 + 7 * MOTOR_SLOTS + 4 => m.reserve[k - 2 - 7 * MOTOR_SLOTS] ^= 1,
            _ => return false,
        }
        true
    }

    /// As [`poke_cmd`] for a state: 4 header fields, 14 IMU fields, 15 per slot, 40 + 4 bytes
    /// and words.
    fn poke_state(m: &mut LowState, k: usize) -> bool {
        const IMU: usize = 5;
        const SLOTS: usize = IMU + 14;
        const REMOTE: usize = SLOTS + 15 * MOTOR_SLOTS;
        const RESERVE: usize = REMOTE + 40;
        match k {
            0 | 1 => m.version[k] ^= 1,
            2 => m.mode_pr ^= 1,
            3 => m.mode_machine ^= 1,
            4 => m.tick ^= 1,
            k if k < IMU + 4 => m.imu_state.quaternion[k - IMU] += 1.0,
            k if k < IMU + 7 => m.imu_state.gyroscope[k - IMU - 4] += 1.0,
            k if k < IMU + 10 => m.imu_state.accelerometer[k - IMU - 7] += 1.0,
            k if k < IMU + 13 => m.imu_state.rpy[k - IMU - 10] += 1.0,
            k if k < SLOTS => m.imu_state.temperature ^= 1,
            k if k < REMOTE => {
                let s = &mut m.motor_state[(k - SLOTS) / 15];
                match (k - SLOTS) % 15 {
                    0 => s.mode ^= 1,
                    1 => s.q += 1.0,
                    2 => s.dq += 1.0,
                    3 => s.ddq += 1.0,
                    4 => s.tau_est += 1.0,
                    i @ 5..=6 => s.temperature[i - 5] ^= 1,
                    7 => s.vol += 1.0,
                    i @ 8..=9 => s.sensor[i - 8] ^= 1,
                    10 => s.motorstate ^= 1,
                    i => s.reserve[i - 11] ^= 1,
                }
            }
            k if k < RESERVE => m.wireless_remote[k - REMOTE] ^= 1,
            k if k < RESERVE + 4 => m.reserve[k - RESERVE] ^= 1,
            _ => return false,
        }
        true
    }

    #[test]
    fn the_crc_of_zeros_is_fixed_and_every_field_changes_it() {
        let zero = LowCmd::default();
        let base = zero.compute_crc();
        assert_eq!(base, crc32_words(&[0; LOW_CMD_IMAGE_SIZE / 4 - 1]));
        assert_eq!(base, LowCmd::default().compute_crc());
        let mut fields = 0;
        loop {
            let mut m = zero.clone();
            if !poke_cmd(&mut m, fields) {
                break;
            }
            assert_ne!(m.compute_crc(), base, "LowCmd field {fields}");
            fields += 1;
        }
        assert_eq!(fields, 2 + 7 * MOTOR_SLOTS + 4);
        let mut m = zero.clone();
        m.crc = 0xdead_beef;
        assert_eq!(m.compute_crc(), base, "the crc word is not covered");
        m.seal();
        assert!(m.crc_ok() && m.crc == base);
        m.motor_cmd[20].kp = 1e-30;
        assert!(!m.crc_ok());

        let zero = LowState::default();
        let base = zero.compute_crc();
        assert_eq!(base, crc32_words(&[0; LOW_STATE_IMAGE_SIZE / 4 - 1]));
        let mut fields = 0;
        loop {
            let mut m = zero.clone();
            if !poke_state(&mut m, fields) {
                break;
            }
            assert_ne!(m.compute_crc(), base, "LowState field {fields}");
            fields += 1;
        }
        assert_eq!(fields, 5 + 14 + 15 * MOTOR_SLOTS + 40 + 4);
        let mut m = sample_state(&mut Gen(7));
        assert!(!m.crc_ok());
        m.seal();
        assert!(m.crc_ok());
    }

    #[test]
    fn padding_bytes_of_the_image_are_zero() {
        // The C padding: 2 bytes after the modes and after the IMU's temperature, 3 after each
        // slot's mode; whatever the fields hold, these stay zero.
        let img = sample_state(&mut Gen(11)).struct_image();
        for at in [10, 11, 70, 71] {
            assert_eq!(img[at], 0, "LowState_ padding at {at}");
        }
        for slot in 0..MOTOR_SLOTS {
            let at = 72 + 56 * slot;
            assert_ne!(img[at], 0, "slot {slot}'s mode");
            assert_eq!(img[at + 1..at + 4], [0, 0, 0], "slot {slot}");
        }
        let img = sample_cmd(&mut Gen(12)).struct_image();
        assert_eq!(img[2..4], [0, 0]);
        for slot in 0..MOTOR_SLOTS {
            let at = 4 + 28 * slot;
            assert_ne!(img[at], 0, "slot {slot}'s mode");
            assert_eq!(img[at + 1..at + 4], [0, 0, 0], "slot {slot}");
        }
    }

    #[test]
    fn decode_refuses_bad_input_and_never_panics() {
        let mut cmd = Vec::new();
        sample_cmd(&mut Gen(8)).encode_cdr(&mut cmd);
        let mut state = Vec::new();
        sample_state(&mut Gen(9)).encode_cdr(&mut state);

        assert_eq!(LowCmd::decode_cdr(&[]), Err(WireError::TooShort { got: 0 }));
        assert_eq!(
            LowState::decode_cdr(&[0, 1, 0]),
            Err(WireError::TooShort { got: 3 })
        );
        for id in [[0x00, 0x00], [0x00, 0x07], [0x00, 0x11], [0x01, 0x00]] {
            let mut b = cmd.clone();
            b[..2].copy_from_slice(&id);
            let e = LowCmd::decode_cdr(&b).unwrap_err();
            assert_eq!(e, WireError::BadEncapsulation { id });
            assert!(e.to_string().contains("not CDR_LE"), "{e}");
        }
        // Every truncation of both samples.
        for n in 0..cmd.len() {
            assert!(LowCmd::decode_cdr(&cmd[..n]).is_err(), "{n} bytes");
        }
        for n in 0..state.len() {
            assert!(LowState::decode_cdr(&state[..n]).is_err(), "{n} bytes");
        }
        let e = LowCmd::decode_cdr(&cmd[..500]).unwrap_err();
        assert_eq!(
            e,
            WireError::Truncated {
                type_name: "LowCmd_",
                got: 496,
                want: 1000
            }
        );
        assert!(e.to_string().contains("truncated"), "{e}");
        let mut long = state.clone();
        long.push(0);
        let e = LowState::decode_cdr(&long).unwrap_err();
        assert_eq!(
            e,
            WireError::Trailing {
                type_name: "LowState_",
                extra: 1
            }
        );
        assert!(e.to_string().contains("1 extra bytes"), "{e}");
        // A sample of the other type.
        assert!(LowCmd::decode_cdr(&state).is_err());
        assert!(LowState::decode_cdr(&cmd).is_err());
        // Random buffers, with and without a valid header: any bytes of the right length are a
        // message (every bit pattern is a value), anything else an error.
        let mut g = Gen(10);
        for i in 0..2000 {
            let len = match i % 4 {
                0 => LOW_CMD_CDR_SIZE,
                1 => LOW_STATE_CDR_SIZE,
                _ => (g.next() % 2200) as usize,
            };
            let mut b: Vec<u8> = (0..len).map(|_| g.next() as u8).collect();
            if i % 3 != 0 && len >= 4 {
                b[..4].copy_from_slice(&CDR_LE);
            }
            let framed = b.len() >= 2 && b[..2] == CDR_LE[..2];
            assert_eq!(
                LowCmd::decode_cdr(&b).is_ok(),
                framed && len == LOW_CMD_CDR_SIZE
            );
            assert_eq!(
                LowState::decode_cdr(&b).is_ok(),
                framed && len == LOW_STATE_CDR_SIZE
            );
        }
    }

    #[test]
    fn encode_reuses_the_buffer() {
        let m = LowState::default();
        let mut buf = Vec::new();
        m.encode_cdr(&mut buf);
        let (ptr, cap) = (buf.as_ptr(), buf.capacity());
        for _ in 0..3 {
            m.encode_cdr(&mut buf);
            assert_eq!(buf.len(), LOW_STATE_CDR_SIZE);
        }
        assert_eq!((buf.as_ptr(), buf.capacity()), (ptr, cap));
    }
}
