//! fovea.toml through the harness frame loop on the simulated Quest 3: the application's section
//! wins over the global one and over the application's own profile, a bad value warns once with the
//! file, line, key and accepted values while the rest applies, the file is re-read while the app
//! runs, numbers parse the same under a German locale, and the log goes by default to
//! `$XDG_STATE_HOME/fovea/fovea.log`, which starts with the instance header. One test function in a
//! process of its own: the log and the XDG folders are process-wide.

use fovea_harness::app::API_1_0;
use fovea_harness::frame_loop::FOVEATION_EXTENSIONS;
use fovea_harness::{sim, App, Chain};
use openxr_sys as xr;

use crate::support::{foveated_loop, in_own_process};

fn fov_values(text: &str) -> Vec<String> {
    text.lines()
        .filter(|l| l.contains(fovea_abi::log_target::STATS))
        .map(|l| {
            let at = l.find("Fov=").expect("Fov= in the stats line") + 4;
            l[at..].split(' ').next().unwrap().to_string()
        })
        .collect()
}

#[test]
fn per_app_sections_apply_and_reload_in_the_frame_loop() {
    in_own_process(
        module_path!(),
        "per_app_sections_apply_and_reload_in_the_frame_loop",
        per_app_sections_here,
    );
}

fn per_app_sections_here() {
    let dir = std::env::temp_dir().join(format!("fovea-settings-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let config = dir.join("config/fovea/fovea.toml");
    std::fs::create_dir_all(config.parent().unwrap()).unwrap();
    std::fs::write(
        &config,
        "level = \"low\"\ndynamic = false\nvertical_offset = 2.5\n\n[app.\"fovea-harness\"]\n\
         level = \"medium\"\nmax_fragment = 3\n\n[engine.\"Unity\"]\nlevel = 3\n",
    )
    .unwrap();
    std::env::set_var("XDG_CONFIG_HOME", dir.join("config"));
    std::env::set_var("XDG_STATE_HOME", dir.join("state"));
    std::env::remove_var("FOVEA_LOG_FILE");
    std::env::remove_var("FOVEA_CONFIG");
    // A locale with a decimal comma: the file's 2.5 still reads as two and a half (Rust's number
    // parsing knows no locale), and nothing in the file is misread.
    std::env::set_var("LC_ALL", "de_DE.UTF-8");
    std::env::set_var("LC_NUMERIC", "de_DE.UTF-8");
    std::env::set_var(
        "FOVEA_LOG",
        format!("warn,{}=info", fovea_abi::log_target::STATS),
    );
    let log = dir.join("state/fovea/fovea.log");

    let mut cfg =
        sim::control::SimConfig::for_headset(fovea_model::headsets::by_id("quest3").unwrap());
    cfg.journal = false;
    sim::control::set_thread_config(Some(cfg));
    let app = App::new(Chain::fovea().unwrap(), &FOVEATION_EXTENSIONS, API_1_0).unwrap();
    let mut lp = foveated_loop(app);
    // The application asks for HIGH; the file's section for it says MEDIUM.
    lp.apply_profile(xr::FoveationLevelFB::HIGH, xr::FoveationDynamicFB::DISABLED)
        .unwrap();
    for _ in 0..200 {
        lp.frame().unwrap();
    }
    let text = std::fs::read_to_string(&log).expect("the default log file");
    let header = text
        .lines()
        .find(|l| l.starts_with("==== fovea "))
        .expect("an instance header");
    for part in [
        "app=\"fovea-harness\"",
        "engine=\"\"",
        "runtime=\"",
        "provided=[",
    ] {
        assert!(header.contains(part), "{part} in {header}");
    }
    assert!(header.contains(&*config.display().to_string()), "{header}");
    let fov = fov_values(&text);
    assert_eq!(fov.last().map(String::as_str), Some("2"), "{text}");
    let warnings: Vec<&str> = text
        .lines()
        .filter(|l| l.contains("configuration:"))
        .collect();
    assert_eq!(warnings.len(), 1, "{text}");
    let want = format!("{}:7: max_fragment: bad value 3", config.display());
    assert!(warnings[0].contains(&want), "{}", warnings[0]);
    assert!(warnings[0].contains("1, 2 or 4"), "{}", warnings[0]);

    // Rewritten while the app runs: the global level now applies, the app section is gone.
    let mark = text.len();
    std::fs::write(
        &config,
        "level = 1\ndynamic = false\n# longer than before\n",
    )
    .unwrap();
    for _ in 0..300 {
        lp.frame().unwrap();
    }
    let text = std::fs::read_to_string(&log).unwrap();
    let fov = fov_values(&text[mark..]);
    assert_eq!(fov.last().map(String::as_str), Some("1"), "{fov:?}");
    assert!(
        !text[mark..].contains("configuration:"),
        "a good file warns about nothing"
    );
    drop(lp);
    std::fs::remove_dir_all(&dir).ok();
}

/// Numbers in fovea.toml read the same inside an application whose C locale writes decimals with a
/// comma (German): after `setlocale(LC_ALL, "de_DE.UTF-8")`, as a C or C++ application may call, the
/// C library's decimal point is "," and fovea still reads `vertical_offset = 2.5` as two and a half
/// and refuses `2,5`. In a process of its own: the C locale is process-wide.
#[test]
fn numbers_read_the_same_under_a_decimal_comma_locale() {
    in_own_process(
        module_path!(),
        "numbers_read_the_same_under_a_decimal_comma_locale",
        decimal_comma_here,
    );
}

/// glibc's `LC_ALL` category (locale.h).
const LC_ALL: std::ffi::c_int = 6;

extern "C" {
    fn setlocale(
        category: std::ffi::c_int,
        locale: *const std::ffi::c_char,
    ) -> *mut std::ffi::c_char;
    fn localeconv() -> *const LConv;
}

/// The head of C's `struct lconv`: `decimal_point` is its first member (locale.h).
#[repr(C)]
struct LConv {
    decimal_point: *const std::ffi::c_char,
}

fn decimal_comma_here() {
    // SAFETY: a NUL-terminated locale name; this child process runs this one test, on one thread.
    let set = unsafe { setlocale(LC_ALL, c"de_DE.UTF-8".as_ptr()) };
    if set.is_null() {
        fovea_harness::skip("the de_DE.UTF-8 locale is not generated (locales; localedef)");
        return;
    }
    // SAFETY: localeconv returns the C library's static struct, valid until the next setlocale.
    let point = unsafe { std::ffi::CStr::from_ptr((*localeconv()).decimal_point) };
    assert_eq!(
        point.to_bytes(),
        b",",
        "the C locale writes decimals with a comma"
    );

    let path = std::path::Path::new("fovea.toml");
    let id = fovea_config::Identity::default();
    let good = fovea_config::Config::parse("vertical_offset = 2.5\n", path);
    assert!(good.problems.is_empty(), "{:?}", good.problems);
    let (resolved, _) = fovea_config::resolve(Some(&good), &id, |_| None);
    assert_eq!(resolved.vertical_offset_deg(), Some(2.5));
    let comma = fovea_config::Config::parse("vertical_offset = 2,5\nlevel = \"low\"\n", path);
    assert_eq!(comma.problems.len(), 1, "{:?}", comma.problems);
    assert_eq!(comma.problems[0].line, 1);
    let (resolved, _) = fovea_config::resolve(Some(&comma), &id, |_| None);
    assert_eq!(resolved.vertical_offset_deg(), None);
    assert_eq!(
        resolved.level(fovea_config::Key::Level),
        Some(fovea_model::density::Level::Low),
        "the rest of the file applies"
    );
}
