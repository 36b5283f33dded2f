//! The gaze fovea's layer located, read back from its `trace` lines on `fovea::gaze` (one a frame,
//! written by `src/xr/gaze.rs`): what the gaze tests compare with the gaze they scripted.

use fovea_model::gaze::Tracking;

/// The gaze the layer located for one frame, from its `trace` line.
#[derive(Clone, Debug, PartialEq)]
pub struct Located {
    pub time_ns: i64,
    pub tracking: Tracking,
    pub angles: [f32; 2],
    pub weight: f32,
    pub ndc: Vec<[f32; 2]>,
}

/// The value of `name=` in a log line (a bracketed list whole).
fn field<'a>(line: &'a str, name: &str) -> &'a str {
    let at = line
        .find(&format!(" {name}="))
        .unwrap_or_else(|| panic!("{name}= in {line}"))
        + name.len()
        + 2;
    let rest = &line[at..];
    if rest.starts_with('[') {
        let end = rest.find("]]").map_or(rest.len(), |e| e + 2);
        &rest[..end]
    } else {
        rest.split(' ').next().unwrap()
    }
}

/// Every located gaze among the log's `lines`, in order.
pub fn located<S: AsRef<str>>(lines: impl IntoIterator<Item = S>) -> Vec<Located> {
    lines
        .into_iter()
        .filter(|l| {
            let l = l.as_ref();
            l.contains(fovea_abi::log_target::GAZE) && l.contains(" time_ns=")
        })
        .map(|l| {
            let l = l.as_ref();
            let tracking = match field(l, "tracking") {
                "Tracked" => Tracking::Tracked,
                "Held" => Tracking::Held,
                "Returning" => Tracking::Returning,
                "Fixed" => Tracking::Fixed,
                other => panic!("tracking {other:?} in {l}"),
            };
            let num = |n: &str| field(l, n).parse::<f32>().unwrap();
            let ndc = field(l, "ndc")
                .trim_matches(|c| c == '[' || c == ']')
                .split("], [")
                .map(|p| {
                    let v: Vec<f32> = p.split(", ").map(|x| x.parse().unwrap()).collect();
                    [v[0], v[1]]
                })
                .collect();
            Located {
                time_ns: field(l, "time_ns").parse().unwrap(),
                tracking,
                angles: [num("yaw"), num("pitch")],
                weight: num("weight"),
                ndc,
            }
        })
        .collect()
}
