//! Logging through `tracing`.
//!
//! `FOVEA_LOG` takes an `EnvFilter` string (default: warnings); lines go to stderr and, with
//! `FOVEA_LOG_FILE`, to that file as well (VR apps often have no console). The subscriber is set
//! once per process, on the first call into the layer; when the application already installed a
//! global subscriber of its own (same `tracing` copy), fovea's lines go there instead.

use std::fs::OpenOptions;
use std::io::Write;
use std::sync::{Arc, Once};

use parking_lot::Mutex;
use tracing_subscriber::fmt::MakeWriter;
use tracing_subscriber::EnvFilter;

/// Environment variable holding the log filter.
pub const LOG_ENV: &str = "FOVEA_LOG";
/// Environment variable naming a file that receives a copy of every line.
pub const LOG_FILE_ENV: &str = "FOVEA_LOG_FILE";

/// Writes each line to stderr and, when configured, to a file.
#[derive(Clone)]
struct Tee {
    file: Option<Arc<Mutex<std::fs::File>>>,
}

struct TeeWriter<'a>(&'a Tee);

impl Write for TeeWriter<'_> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if let Some(f) = &self.0.file {
            // A full disk must not take the application down; the stderr copy still goes out.
            let _ = f.lock().write_all(buf);
        }
        std::io::stderr().write_all(buf)?;
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        if let Some(f) = &self.0.file {
            let _ = f.lock().flush();
        }
        std::io::stderr().flush()
    }
}

impl<'a> MakeWriter<'a> for Tee {
    type Writer = TeeWriter<'a>;

    fn make_writer(&'a self) -> Self::Writer {
        TeeWriter(self)
    }
}

/// Installs the subscriber once. Safe to call from every entry point.
pub fn init() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let filter = EnvFilter::try_from_env(LOG_ENV).unwrap_or_else(|_| EnvFilter::new("warn"));
        let file = std::env::var_os(LOG_FILE_ENV).and_then(|path| {
            match OpenOptions::new().create(true).append(true).open(&path) {
                Ok(f) => Some(Arc::new(Mutex::new(f))),
                Err(e) => {
                    eprintln!(
                        "fovea: cannot open {LOG_FILE_ENV}={}: {e}",
                        path.to_string_lossy()
                    );
                    None
                }
            }
        });
        let subscriber = tracing_subscriber::fmt()
            .with_env_filter(filter)
            .with_writer(Tee { file })
            .with_ansi(false)
            .with_target(true)
            .finish();
        let _ = tracing::subscriber::set_global_default(subscriber);
    });
}
