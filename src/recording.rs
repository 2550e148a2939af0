//! Where a process's rerun recording goes: its `.rrd` file, and a live viewer as well when one
//! is given (rerun's gRPC proxy URL, e.g. `rerun+http://127.0.0.1:9876/proxy`, what `rerun`
//! listens on by default). The loggers' threads stream to both; the control loop never waits
//! for either (it hands records to its logger thread, dropping them when that one lags).

use std::path::Path;

use rerun::sink::{FileSink, GrpcSink};

/// A recording stream writing `path`, streaming to `live` too when given.
pub fn open(
    path: &Path,
    recording_id: Option<&str>,
    live: Option<&str>,
) -> Result<rerun::RecordingStream, Box<dyn std::error::Error + Send + Sync>> {
    let mut b = rerun::RecordingStreamBuilder::new("upc");
    if let Some(id) = recording_id {
        b = b.recording_id(id);
    }
    let file = FileSink::new(path).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(match live {
        None => b.set_sinks((file,))?,
        Some(url) => {
            let uri = url.parse().map_err(|e| {
                format!("--connect {url}: not a rerun gRPC proxy URL (rerun+http://HOST:PORT/proxy): {e}")
            })?;
            tracing::info!("streaming the recording to a live viewer at {url} as well");
            b.set_sinks((file, GrpcSink::new(uri)))?
        }
    })
}
