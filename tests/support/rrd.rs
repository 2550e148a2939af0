//! Reading back the `.rrd` recordings.

use std::path::Path;

/// Every record in a `.rrd` (it must decode to the end): distinct `sim_time` stamps of the
/// entities under `prefix`, and the largest.
pub fn rrd_times(p: &Path, prefix: &str) -> (usize, f64) {
    let file = std::fs::File::open(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    let mut stamps = std::collections::BTreeSet::new();
    for msg in re_log_encoding::DecoderApp::decode_lazy(std::io::BufReader::new(file)) {
        let msg = msg.unwrap_or_else(|e| panic!("{} does not decode: {e}", p.display()));
        if let re_log_types::LogMsg::ArrowMsg(_, arrow) = msg {
            let chunk = re_chunk::Chunk::from_arrow_msg(&arrow).expect("chunk");
            if !chunk.entity_path().to_string().starts_with(prefix) {
                continue;
            }
            for (name, col) in chunk.timelines() {
                if name.as_str() == "sim_time" {
                    stamps.extend(col.times_raw().iter().copied());
                }
            }
        }
    }
    let last = stamps.last().copied().unwrap_or(0) as f64 * 1e-9;
    (stamps.len(), last)
}
