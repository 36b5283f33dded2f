//! `fovea fov --headset NAME [--json]`: each eye's FOV and projection centre, and the recommended
//! eye-buffer size with the asymmetric FOVs against one shared symmetric FOV (asymmetric FOV FAQ).

use fovea_model::density::{Grid, Rect, View};
use fovea_model::headsets::{by_id, ids, Headset};

use crate::args::Args;

/// Resolves `--headset`, naming the accepted values when it is wrong.
pub fn headset(args: &Args) -> Result<&'static Headset, String> {
    let id = args.required("headset")?;
    by_id(id).ok_or_else(|| {
        format!(
            "unknown headset '{id}'; accepted: {}",
            ids().collect::<Vec<_>>().join(", ")
        )
    })
}

pub fn run(args: &Args) -> Result<(), String> {
    let h = headset(args)?;
    let [aw, ah] = h.recommended_size();
    let [sw, sh] = h.symmetric_size();
    let saving = h.symmetric_pixel_saving();
    let eyes: Vec<(&str, [f64; 4], [f32; 2])> = ["left", "right"]
        .iter()
        .zip(h.fovs())
        .map(|(name, f)| (*name, f.degrees(), f.projection_center_ndc()))
        .collect();
    if args.switch("json") {
        let eyes_json: Vec<String> = eyes
            .iter()
            .map(|(name, [l, r, u, d], [x, y])| {
                format!(
                    "{{\"eye\":\"{name}\",\"fov_deg\":{{\"left\":{l:.4},\"right\":{r:.4},\"up\":{u:.4},\"down\":{d:.4}}},\
                     \"projection_center_ndc\":[{x:.6},{y:.6}]}}"
                )
            })
            .collect();
        println!(
            "{{\"headset\":\"{}\",\"eyes\":[{}],\"recommended\":{{\"asymmetric\":[{aw},{ah}],\"symmetric\":[{sw},{sh}]}},\
             \"symmetric_pixel_saving\":{saving:.6}}}",
            h.id,
            eyes_json.join(",")
        );
        return Ok(());
    }
    println!("{} ({})", h.name, h.source);
    println!(
        "{:<6} {:>7} {:>7} {:>7} {:>7}   projection centre (NDC)",
        "eye", "left", "right", "up", "down"
    );
    for (name, [l, r, u, d], [x, y]) in &eyes {
        println!("{name:<6} {l:>6.2}° {r:>6.2}° {u:>6.2}° {d:>6.2}°   ({x:+.3}, {y:+.3})");
    }
    println!("recommended per eye: asymmetric {aw}x{ah}, symmetric {sw}x{sh}, asymmetric saves {:.1}% of pixels", saving * 100.0);
    Ok(())
}

/// One eye of a preset at its recommended size, as the density model sees it.
pub fn eye_view(h: &Headset, eye: usize, texel: u32) -> (Grid, View) {
    let [w, hh] = h.recommended_size();
    let view = View {
        fov: h.fovs()[eye],
        rect: Rect {
            x: 0,
            y: 0,
            width: w,
            height: hh,
        },
        visible: None,
    };
    (Grid::new([w, hh], [texel, texel]), view)
}

/// Resolves `--texel` (default 32): the density map texel size in pixels.
pub fn texel(args: &Args) -> Result<u32, String> {
    let t: u32 = args.parsed_or("texel", 32)?;
    if !(1..=1024).contains(&t) {
        return Err(format!("--texel {t}: expected 1..1024 pixels"));
    }
    Ok(t)
}
