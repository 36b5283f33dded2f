//! Logging through `tracing`.
//!
//! `FOVEA_LOG` takes an `EnvFilter` string (default: warnings, or the configuration file's `log`);
//! lines go to stderr and to a log file: `$XDG_STATE_HOME/fovea/fovea.log` by default (VR apps
//! rarely have a console), the file `FOVEA_LOG_FILE` or the configuration file's `log_file` names,
//! none when either is empty. The file is appended to and rotated: at [`LOG_ROTATE_BYTES`] it
//! becomes `fovea.log.1` (replacing the previous one) and a new file starts, so two files at most
//! ever exist. The subscriber is set once per process, on the first call into the layer; the
//! configuration file's `log` and `log_file` apply from `xrCreateInstance`, when the application's
//! sections are known ([`configure`]). When the application already installed a global subscriber
//! of its own (same `tracing` copy), fovea's lines go there instead.

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Once, OnceLock};

use parking_lot::Mutex;
use tracing_subscriber::fmt::MakeWriter;
use tracing_subscriber::EnvFilter;

pub use fovea_config::LOG_ROTATE_BYTES;

/// Environment variable holding the log filter.
pub const LOG_ENV: &str = fovea_abi::env::LOG;
/// Environment variable naming the log file; empty: no log file.
pub const LOG_FILE_ENV: &str = fovea_abi::env::LOG_FILE;

/// An open log file, rotated at a size.
pub struct LogFile {
    file: File,
    path: PathBuf,
    written: u64,
    limit: u64,
}

impl LogFile {
    /// Opens `path` for appending (creating its folder), rotating at `limit` bytes.
    pub fn open(path: &Path, limit: u64) -> std::io::Result<LogFile> {
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir)?;
        }
        let file = OpenOptions::new().create(true).append(true).open(path)?;
        let written = file.metadata().map(|m| m.len()).unwrap_or(0);
        Ok(LogFile {
            file,
            path: path.to_path_buf(),
            written,
            limit,
        })
    }

    /// The rotated copy: `fovea.log.1` for `fovea.log`.
    pub fn rotated(path: &Path) -> PathBuf {
        let mut p = path.as_os_str().to_owned();
        p.push(".1");
        PathBuf::from(p)
    }

    /// Appends `buf`, first rotating when it would take the file past its limit.
    pub fn write(&mut self, buf: &[u8]) -> std::io::Result<()> {
        if self.written > 0 && self.written + buf.len() as u64 > self.limit {
            let _ = std::fs::rename(&self.path, LogFile::rotated(&self.path));
            self.file = OpenOptions::new()
                .create(true)
                .append(true)
                .open(&self.path)?;
            self.written = 0;
        }
        self.file.write_all(buf)?;
        self.written += buf.len() as u64;
        Ok(())
    }
}

/// Writes each line to stderr and, when configured, to the log file.
#[derive(Clone)]
struct Tee {
    file: Arc<Mutex<Option<LogFile>>>,
}

struct TeeWriter<'a>(&'a Tee);

impl Write for TeeWriter<'_> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if let Some(f) = self.0.file.lock().as_mut() {
            // A full disk must not take the application down; the stderr copy still goes out.
            let _ = f.write(buf);
        }
        std::io::stderr().write_all(buf)?;
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        if let Some(f) = self.0.file.lock().as_mut() {
            let _ = f.file.flush();
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

/// What [`configure`] changes after [`init`].
struct Live {
    file: Arc<Mutex<Option<LogFile>>>,
    /// The file open now (`None`: none).
    path: Mutex<Option<PathBuf>>,
    reload: Box<dyn Fn(EnvFilter) -> bool + Send + Sync>,
}

static LIVE: OnceLock<Live> = OnceLock::new();

/// The log file in force before the configuration file is read: `FOVEA_LOG_FILE` (empty: none),
/// else the default under `$XDG_STATE_HOME`.
fn initial_path() -> Option<PathBuf> {
    match std::env::var_os(LOG_FILE_ENV) {
        Some(p) if p.is_empty() => None,
        Some(p) => Some(PathBuf::from(p)),
        None => fovea_config::default_log_path(fovea_config::process_env),
    }
}

fn open(path: &Path) -> Option<LogFile> {
    match LogFile::open(path, LOG_ROTATE_BYTES) {
        Ok(f) => Some(f),
        Err(e) => {
            eprintln!("fovea: cannot open the log file {}: {e}", path.display());
            None
        }
    }
}

/// Installs the subscriber once. Safe to call from every entry point.
pub fn init() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let filter = EnvFilter::try_from_env(LOG_ENV)
            .unwrap_or_else(|_| EnvFilter::new(fovea_config::DEFAULT_LOG));
        let path = initial_path();
        let file = Arc::new(Mutex::new(path.as_deref().and_then(open)));
        let builder = tracing_subscriber::fmt()
            .with_env_filter(filter)
            .with_writer(Tee { file: file.clone() })
            .with_ansi(false)
            .with_target(true)
            .with_filter_reloading();
        let handle = builder.reload_handle();
        let subscriber = builder.finish();
        let _ = tracing::subscriber::set_global_default(subscriber);
        let _ = LIVE.set(Live {
            path: Mutex::new(path.filter(|_| file.lock().is_some())),
            file,
            reload: Box::new(move |f| handle.reload(f).is_ok()),
        });
    });
}

/// Applies the configuration file's `log` filter (unless `FOVEA_LOG` is set) and `log_file`
/// (`Some("")`: no file; `None`: the default), once the instance's sections are known.
pub fn configure(log: Option<&str>, log_file: Option<&str>) {
    init();
    let Some(live) = LIVE.get() else { return };
    if let Some(filter) = log.filter(|_| std::env::var_os(LOG_ENV).is_none()) {
        match EnvFilter::try_new(filter) {
            Ok(f) => {
                (live.reload)(f);
            }
            Err(e) => tracing::warn!(log = filter, error = %e, "bad log filter; ignored"),
        }
    }
    let want = match log_file {
        Some("") => None,
        Some(p) => Some(PathBuf::from(p)),
        None => initial_path(),
    };
    let mut now = live.path.lock();
    if *now != want {
        *live.file.lock() = want.as_deref().and_then(open);
        *now = want.filter(|_| live.file.lock().is_some());
    }
}

/// Writes one header line straight to the log file (not to stderr, whatever the filter): the
/// instance header each run starts with.
pub fn header(line: &str) {
    init();
    let Some(live) = LIVE.get() else { return };
    if let Some(f) = live.file.lock().as_mut() {
        let _ = f.write(format!("\n==== {line}\n").as_bytes());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_log_file_rotates_and_never_grows_past_two_files() {
        let dir = std::env::temp_dir().join(format!("fovea-log-rotation-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let path = dir.join("state/fovea/fovea.log");
        let mut f = LogFile::open(&path, 100).unwrap();
        let line = [b'x'; 29];
        for _ in 0..3 {
            f.write(&line).unwrap();
        }
        assert_eq!(std::fs::metadata(&path).unwrap().len(), 87);
        assert!(!LogFile::rotated(&path).exists());
        f.write(&line).unwrap();
        assert_eq!(std::fs::metadata(&path).unwrap().len(), 29, "rotated");
        assert_eq!(
            std::fs::metadata(LogFile::rotated(&path)).unwrap().len(),
            87
        );
        for _ in 0..20 {
            f.write(&line).unwrap();
        }
        let files = std::fs::read_dir(path.parent().unwrap()).unwrap().count();
        assert_eq!(files, 2, "fovea.log and fovea.log.1 only");
        assert!(std::fs::metadata(&path).unwrap().len() <= 100);
        // Reopened, the size so far counts.
        drop(f);
        let mut f = LogFile::open(&path, 100).unwrap();
        let before = std::fs::metadata(&path).unwrap().len();
        for _ in 0..4 {
            f.write(&line).unwrap();
        }
        assert!(std::fs::metadata(&path).unwrap().len() <= 100, "{before}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
