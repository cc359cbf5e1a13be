//! The generated chain clips the load runs stream: a clip document from a
//! few numbers, so every run of one size streams frames of the same size.

use serde_json::{Value, json};

/// How a generated chain clip moves: `joints` joints `j0`..`j{n-1}`, each
/// the parent of the next, with a 31-key Catmull-Rom rotation track each
/// (joint `i`'s angle at key `k` is `amplitude · sin(k / period + i)`) and a
/// root translation track moving `stride` per second, `duration` s long,
/// looping. Clips of one size differ only in these numbers, so the clip and
/// motion runs stream the same joints in frames of the same size.
#[derive(Debug, Clone)]
pub struct Chain {
    pub name: String,
    pub joints: usize,
    pub duration: f64,
    pub amplitude: f64,
    /// Keys per radian of the swing.
    pub period: f64,
    pub stride: f64,
}

/// Keys per track of a chain clip.
const CHAIN_KEYS: u32 = 31;

/// The standard load clip (the one `scripts/bench_rest.sh` uses): a chain of
/// `joints` joints, 3 s long (see [`Chain`]).
pub fn chain_clip(joints: usize) -> Value {
    chain(&Chain {
        name: format!("load-chain-{joints}"),
        joints,
        duration: 3.0,
        amplitude: 0.3,
        period: 5.0,
        stride: 1.0,
    })
}

/// The clip document of a [`Chain`].
pub fn chain(c: &Chain) -> Value {
    let skeleton: Vec<Value> = (0..c.joints)
        .map(|i| {
            let parent = (i > 0).then(|| format!("j{}", i - 1));
            json!({"name": format!("j{i}"), "parent": parent, "rest": {"translation": [0.0, 0.1, 0.0]}})
        })
        .collect();
    let last = f64::from(CHAIN_KEYS - 1);
    let times: Vec<f64> = (0..CHAIN_KEYS).map(|k| f64::from(k) * c.duration / last).collect();
    let mut tracks: Vec<Value> = (0..c.joints)
        .map(|i| {
            let values: Vec<[f64; 4]> = (0..CHAIN_KEYS)
                .map(|k| {
                    let a = c.amplitude * (f64::from(k) / c.period + i as f64).sin();
                    [0.0, 0.0, (a / 2.0).sin(), (a / 2.0).cos()]
                })
                .collect();
            json!({"joint": format!("j{i}"), "channel": "rotation", "interpolation": "catmull_rom",
                   "times": times, "values": values})
        })
        .collect();
    let path: Vec<[f64; 3]> = times.iter().map(|t| [t * c.stride, 0.0, 0.0]).collect();
    tracks.push(json!({"joint": "j0", "channel": "translation", "interpolation": "catmull_rom",
                       "times": times, "values": path}));
    json!({"name": c.name, "skeleton": {"joints": skeleton}, "tracks": tracks, "playback": "loop"})
}

#[cfg(test)]
mod tests {
    use super::*;
    use formats::wire::json::parse_clip;

    #[test]
    fn the_chain_clip_is_a_valid_clip_of_the_asked_size() {
        let body = serde_json::to_vec(&chain_clip(20)).unwrap();
        let (_, spec) = parse_clip(&body).expect("a valid clip document");
        let clip = anim::Clip::build(&spec).expect("builds");
        assert_eq!(clip.joint_count(), 20);
    }
}
