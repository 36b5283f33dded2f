//! include/fovea.h: compiles as C99 and C++ with `-Wall -Wextra -Werror`, with and without the
//! OpenXR SDK headers; a program built against it dlopen()s this build's libfovea.so and finds the
//! symbol it declares (and, with the SDK's types, negotiates); and its layer names, extension list
//! and environment variables are the ones in the Rust sources, so the header cannot drift.
//!
//! Needs `cc` (gcc) and, for the C++ half, `c++`; without them the test prints `SKIPPED` (fails under
//! `FOVEA_REQUIRE_SYSTEM=1`).

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

use fovea_abi::EXTENSIONS;
use fovea_harness::{artifact, skip};

use crate::support::{root, rust_files};

fn header() -> String {
    std::fs::read_to_string(root().join("include/fovea.h")).unwrap()
}

/// `#define NAME VALUE` lines whose name starts with `prefix`, in order.
fn defines(header: &str, prefix: &str) -> Vec<(String, String)> {
    header
        .lines()
        .filter_map(|l| l.trim().strip_prefix("#define "))
        .filter_map(|l| {
            let (name, rest) = l.split_once(char::is_whitespace)?;
            // The value up to a trailing comment.
            let value = rest.split("/*").next().unwrap().trim();
            (name.starts_with(prefix) && !name.contains('(') && !value.is_empty())
                .then(|| (name.to_owned(), value.to_owned()))
        })
        .collect()
}

fn unquote(v: &str) -> &str {
    v.strip_prefix('"')
        .and_then(|v| v.strip_suffix('"'))
        .unwrap_or_else(|| panic!("{v} is not a string literal"))
}

/// The environment variables the layer reads: every all-caps `"NAME_WITH_UNDERSCORES"` string
/// literal in the layer's sources (src/, not the CLI in src/bin), which is how settings.rs, log.rs
/// and ffi.rs name them, plus the implicit manifest's `disable_environment`, which the loader reads.
/// `c"..."`/`b"..."` literals and `XR_`/`VK_` names are API identifiers, not variables.
fn layer_env_vars() -> BTreeSet<String> {
    // The layer, the configuration crate it reads its file and variables through, and the ABI crate
    // that names them.
    let mut files = rust_files(&root().join("src"));
    files.extend(rust_files(&root().join("crates/config/src")));
    files.extend(rust_files(&root().join("crates/abi/src")));
    let mut vars = BTreeSet::new();
    for f in files
        .iter()
        .filter(|f| !f.starts_with(root().join("src/bin")))
    {
        let text = std::fs::read_to_string(f).unwrap();
        let bytes = text.as_bytes();
        let mut at = 0;
        while let Some(open) = text[at..].find('"').map(|i| at + i) {
            at = open + 1;
            let token: String = text[at..]
                .chars()
                .take_while(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || *c == '_')
                .collect();
            let closed = bytes.get(at + token.len()) == Some(&b'"');
            let prefixed = open > 0 && matches!(bytes[open - 1], b'c' | b'b' | b'\\');
            if closed
                && !prefixed
                && token.len() > 2
                && token.contains('_')
                && token.starts_with(|c: char| c.is_ascii_uppercase())
                && !token.starts_with("XR_")
                && !token.starts_with("VK_")
                && !token.starts_with("CARGO_")
            {
                vars.insert(token);
            }
        }
    }
    let implicit: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(root().join("manifest/implicit/XR_APILAYER_FOVEA_foveation.json"))
            .unwrap(),
    )
    .unwrap();
    // The implicit Vulkan manifest's enable and disable variables, which the Vulkan loader reads
    // (and the OpenXR side sets the first).
    vars.insert(fovea_abi::env::VK_LAYER.to_owned());
    vars.insert(fovea_abi::env::DISABLE_VK_LAYER.to_owned());
    vars.insert(
        implicit["api_layer"]["disable_environment"]
            .as_str()
            .unwrap()
            .to_owned(),
    );
    vars
}

#[test]
fn header_matches_the_rust_sources() {
    let h = header();
    assert_eq!(
        defines(&h, "FOVEA_LAYER_NAME"),
        [(
            "FOVEA_LAYER_NAME".to_owned(),
            format!("\"{}\"", fovea_abi::LAYER_NAME)
        )]
    );

    assert_eq!(
        defines(&h, "FOVEA_VK_LAYER_NAME"),
        [(
            "FOVEA_VK_LAYER_NAME".to_owned(),
            format!("\"{}\"", fovea_abi::VK_LAYER_NAME)
        )]
    );

    // Extensions: name and version macros in registry order, named after the extension.
    let ext = defines(&h, "FOVEA_EXT_");
    let listed: Vec<(String, u32)> = ext
        .chunks(2)
        .map(|pair| {
            let [(name_macro, name), (version_macro, version)] = pair else {
                panic!("unpaired {pair:?}")
            };
            let name = unquote(name);
            let stem = format!(
                "FOVEA_EXT_{}",
                name.trim_start_matches("XR_").to_uppercase()
            );
            assert_eq!(name_macro, &format!("{stem}_NAME"));
            assert_eq!(version_macro, &format!("{stem}_VERSION"));
            (name.to_owned(), version.parse().unwrap())
        })
        .collect();
    let ours: Vec<(String, u32)> = EXTENSIONS
        .iter()
        .map(|e| (e.name.to_str().unwrap().to_owned(), e.version))
        .collect();
    assert_eq!(listed, ours);
    assert_eq!(
        defines(&h, "FOVEA_EXTENSION_COUNT"),
        [(
            "FOVEA_EXTENSION_COUNT".to_owned(),
            EXTENSIONS.len().to_string()
        )]
    );

    // Environment variables: the macros name exactly what the layer reads.
    let env: BTreeSet<String> = defines(&h, "FOVEA_ENV_")
        .iter()
        .map(|(name, value)| {
            let value = unquote(value);
            assert_eq!(
                name,
                &format!("FOVEA_ENV_{}", value.trim_start_matches("FOVEA_"))
            );
            value.to_owned()
        })
        .collect();
    let sources = layer_env_vars();
    assert!(
        sources.contains("FOVEA_LOG") && sources.contains("DEBUG_OCULUS_FOVEATION_LEVEL"),
        "the source scan finds nothing: {sources:?}"
    );
    assert_eq!(env, sources);
}

/// The program: prints what the X-macros expand to, loads the library and finds the symbol.
const PROGRAM: &str = r#"
#include "fovea.h"

#include <dlfcn.h>
#include <stdio.h>
#include <string.h>

#define EXT_NAME(name, version) name,
#define EXT_VERSION(name, version) version,
#define ENV_NAME(name) name,
static const char *const ext_names[] = {FOVEA_EXTENSIONS(EXT_NAME)};
static const unsigned ext_versions[] = {FOVEA_EXTENSIONS(EXT_VERSION)};
static const char *const env_names[] = {FOVEA_ENV_VARS(ENV_NAME)};

#if defined(XR_LOADER_VERSION_1_0)
/* With the SDK: fovea's numbers are the registry's. openxr.h defines the three non-Vulkan ones. */
#if FOVEA_EXT_FB_SWAPCHAIN_UPDATE_STATE_VERSION != XR_FB_swapchain_update_state_SPEC_VERSION || \
    FOVEA_EXT_FB_FOVEATION_VERSION != XR_FB_foveation_SPEC_VERSION ||                           \
    FOVEA_EXT_FB_FOVEATION_CONFIGURATION_VERSION != XR_FB_foveation_configuration_SPEC_VERSION
#error "fovea.h's extension versions differ from openxr.h"
#endif
#endif

int main(int argc, char **argv) {
    size_t i;
    void *lib;
    void *sym;
    fovea_pfn_negotiate negotiate;
    if (argc != 2) {
        return 64;
    }
    if (sizeof ext_names / sizeof ext_names[0] != FOVEA_EXTENSION_COUNT) {
        fprintf(stderr, "FOVEA_EXTENSIONS has %u entries, FOVEA_EXTENSION_COUNT says %d\n",
                (unsigned)(sizeof ext_names / sizeof ext_names[0]), FOVEA_EXTENSION_COUNT);
        return 2;
    }
    for (i = 0; i < FOVEA_EXTENSION_COUNT; i++) {
        printf("extension %s %u\n", ext_names[i], ext_versions[i]);
    }
    for (i = 0; i < sizeof env_names / sizeof env_names[0]; i++) {
        printf("env %s\n", env_names[i]);
    }
    printf("layer %s\n", FOVEA_LAYER_NAME);
    printf("vulkan layer %s\n", FOVEA_VK_LAYER_NAME);

    /* The declaration and the pointer type agree: comparing distinct function pointer types is an
       error here (-Werror in C, always in C++). Unevaluated, so nothing is linked. */
    (void)sizeof(&xrNegotiateLoaderApiLayerInterface == (fovea_pfn_negotiate)0);

    lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "dlopen: %s\n", dlerror());
        return 3;
    }
    sym = dlsym(lib, "xrNegotiateLoaderApiLayerInterface");
    if (!sym) {
        fprintf(stderr, "dlsym: %s\n", dlerror());
        return 4;
    }
    memcpy(&negotiate, &sym, sizeof negotiate);
    printf("symbol found\n");

#if defined(XR_LOADER_VERSION_1_0)
    {
        /* What the loader sends (docs/openxr-layer.md#loader-negotiation). */
        XrNegotiateLoaderInfo info;
        XrNegotiateApiLayerRequest request;
        XrResult r;
        memset(&info, 0, sizeof info);
        memset(&request, 0, sizeof request);
        info.structType = XR_LOADER_INTERFACE_STRUCT_LOADER_INFO;
        info.structVersion = XR_LOADER_INFO_STRUCT_VERSION;
        info.structSize = sizeof info;
        info.minInterfaceVersion = 1;
        info.maxInterfaceVersion = XR_CURRENT_LOADER_API_LAYER_VERSION;
        info.minApiVersion = XR_MAKE_VERSION(1, 0, 0);
        info.maxApiVersion = XR_MAKE_VERSION(1, 0x3ff, 0xfff);
        request.structType = XR_LOADER_INTERFACE_STRUCT_API_LAYER_REQUEST;
        request.structVersion = XR_API_LAYER_INFO_STRUCT_VERSION;
        request.structSize = sizeof request;
        r = negotiate(&info, FOVEA_LAYER_NAME, &request);
        if (r != XR_SUCCESS || !request.getInstanceProcAddr || !request.createApiLayerInstance) {
            fprintf(stderr, "negotiation: %d\n", (int)r);
            return 5;
        }
        info.structSize -= 1;
        if (negotiate(&info, FOVEA_LAYER_NAME, &request) != XR_ERROR_INITIALIZATION_FAILED) {
            fprintf(stderr, "a wrong structSize was accepted\n");
            return 6;
        }
        printf("negotiated interface %u\n", request.layerInterfaceVersion);
    }
#else
    (void)negotiate;
#endif
    return 0;
}
"#;

/// The OpenXR SDK headers openxr-sys ships, from the cargo registry.
fn sdk_include() -> Option<PathBuf> {
    let home = std::env::var_os("CARGO_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| Path::new(&h).join(".cargo")))?;
    let registry = home.join("registry/src");
    std::fs::read_dir(registry)
        .ok()?
        .flatten()
        .flat_map(|index| {
            std::fs::read_dir(index.path())
                .into_iter()
                .flatten()
                .flatten()
        })
        .map(|krate| krate.path())
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("openxr-sys-"))
        })
        .map(|p| p.join("OpenXR-SDK/include"))
        .find(|p| p.join("openxr/openxr_loader_negotiation.h").is_file())
}

fn have(tool: &str) -> bool {
    Command::new(tool)
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success())
}

/// Compiles the program with `compiler` into `dir/variant` and runs it against `library`; returns
/// its stdout.
fn build_and_run(
    dir: &Path,
    variant: &str,
    compiler: &str,
    flags: &[&str],
    library: &Path,
) -> String {
    let exe = dir.join(variant);
    let out = Command::new(compiler)
        .args(flags)
        .args(["-Wall", "-Wextra", "-Werror", "-I"])
        .arg(root().join("include"))
        .arg("-x")
        .arg(if compiler == "c++" { "c++" } else { "c" })
        .arg(dir.join("program.c"))
        .arg("-o")
        .arg(&exe)
        .arg("-ldl")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{variant}: {compiler} {flags:?}:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let run = Command::new(&exe).arg(library).output().unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout).into_owned();
    assert_eq!(
        run.status.code(),
        Some(0),
        "{variant}: {stdout}{}",
        String::from_utf8_lossy(&run.stderr)
    );
    stdout
}

#[test]
fn a_c_and_a_cpp_program_compile_against_the_header_and_find_the_symbol() {
    if !have("cc") {
        skip("no C compiler (cc): apt-get install gcc");
        return;
    }
    let library = artifact("libfovea.so").expect("libfovea.so");
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("c_header");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("program.c"), PROGRAM).unwrap();

    let sdk = sdk_include();
    if sdk.is_none() {
        skip("the OpenXR SDK headers of openxr-sys are not in the cargo registry");
    }
    let sdk_flag = sdk.map(|p| format!("-I{}", p.display()));
    let mut compilers = vec![("c", "cc", "-std=c99")];
    if have("c++") {
        compilers.push(("cpp", "c++", "-std=c++11"));
    } else {
        skip("no C++ compiler (c++): apt-get install g++");
    }
    let expected: Vec<String> = EXTENSIONS
        .iter()
        .map(|e| format!("extension {} {}", e.name.to_str().unwrap(), e.version))
        .chain(layer_env_vars().iter().map(|v| format!("env {v}")))
        .collect();
    for (lang, compiler, std) in compilers {
        // Without the SDK: the forward-declared types.
        let out = build_and_run(
            &dir,
            &format!("{lang}_without_sdk"),
            compiler,
            &[std, "-DFOVEA_NO_OPENXR_HEADERS"],
            &library,
        );
        let mut printed: Vec<String> = out
            .lines()
            .filter(|l| l.starts_with("extension ") || l.starts_with("env "))
            .map(String::from)
            .collect();
        // The env X-macro lists in the header's order; compare as sets.
        printed[EXTENSIONS.len()..].sort();
        assert_eq!(printed, expected, "{out}");
        assert!(
            out.contains(&format!("layer {}\n", fovea_abi::LAYER_NAME)),
            "{out}"
        );
        assert!(
            out.contains(&format!("vulkan layer {}\n", fovea_abi::VK_LAYER_NAME)),
            "{out}"
        );
        assert!(out.contains("symbol found\n"), "{out}");
        assert!(!out.contains("negotiated"), "{out}");
        // With the SDK's types, and its own prototype of the same function next to ours.
        if let Some(sdk) = &sdk_flag {
            let out = build_and_run(
                &dir,
                &format!("{lang}_with_sdk"),
                compiler,
                &[std, sdk, "-DXR_EXTENSION_PROTOTYPES"],
                &library,
            );
            assert!(out.contains("negotiated interface 1\n"), "{out}");
        }
    }
}
