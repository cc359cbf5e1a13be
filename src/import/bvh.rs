//! BVH (BioVision Hierarchy) motion capture to one clip.
//!
//! The format has no formal spec; this reads what real exporters write
//! (CMU/cgspeed, MotionBuilder, Daz, Blender): CR, LF or mixed line endings,
//! tabs, numbers like `.0083333`, joint names with spaces, several ROOTs,
//! CHANNELS in any order and any subset. The HIERARCHY is parsed with an
//! explicit stack (no recursion, depth-limited); MOTION is read one line per
//! frame, each checked to have exactly the declared number of values, and
//! keys are pushed as lines are read: the `Frames:` header is only compared
//! with what the body actually holds, never used to preallocate.
//!
//! Conventions: a joint's rotation is the product of its rotation channels
//! in the order listed, as matrices acting on column vectors
//! (`Zrotation Xrotation Yrotation` → `R = Rz·Rx·Ry`), angles in degrees;
//! its translation is its position channels where it has them and its
//! OFFSET for the axes it has not; the local transform is `T·R`.

use std::borrow::Cow;

use glam::{DQuat, DVec3, Vec3, Vec4};

use super::{Budget, ImportError, ImportOptions, Imported, clip_name, unique_names};
use crate::anim::{Channel, ClipSpec, Interpolation, JointSpec, Keys, Playback, SkeletonSpec, TrackSpec, Transform};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Dof {
    Position(usize),
    Rotation(usize),
}

struct Joint {
    name: String,
    parent: Option<usize>,
    offset: Option<DVec3>,
    channels: Vec<Dof>,
    end_site: bool,
}

/// A whitespace-separated token and the (1-based) line it is on.
#[derive(Clone, Copy)]
struct Tok<'s> {
    line: usize,
    text: &'s str,
}

pub(crate) fn import(bytes: &[u8], options: &ImportOptions) -> Result<Imported, ImportError> {
    let interpolation = match options.bvh_interpolation {
        i @ (Interpolation::Linear | Interpolation::CatmullRom | Interpolation::Step) => i,
        Interpolation::CubicHermite => {
            return Err(ImportError::Unsupported(
                "BVH frames cannot be imported as cubic_hermite (no tangents)".into(),
            ));
        }
    };
    let text: Cow<str> = String::from_utf8_lossy(bytes);
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    // Lines split on LF; a CR before it (or a lone CR) is whitespace.
    let mut lines = text.split('\n').enumerate().map(|(i, l)| (i + 1, l));

    // The hierarchy's tokens, up to the MOTION line.
    let mut tokens: Vec<Tok> = Vec::new();
    let mut motion_line = None;
    for (n, line) in lines.by_ref() {
        let mut words = line.split_ascii_whitespace().peekable();
        if words.peek().is_some_and(|w| w.eq_ignore_ascii_case("MOTION")) {
            motion_line = Some(n);
            break;
        }
        tokens.extend(words.map(|text| Tok { line: n, text }));
    }
    let joints = parse_hierarchy(&tokens, options)?;
    let Some(motion_line) = motion_line else {
        return Err(ImportError::BvhSyntax {
            line: tokens.last().map_or(1, |t| t.line),
            detail: "no MOTION section".into(),
        });
    };

    // `Frames: N` and `Frame Time: x`, skipping blank lines.
    let mut header = |key: &str| -> Result<(usize, String), ImportError> {
        for (n, line) in lines.by_ref() {
            let trimmed = line.trim();
            if trimmed.is_empty() {
                continue;
            }
            let (name, value) = trimmed.split_once(':').unwrap_or((trimmed, ""));
            let name: String = name.split_ascii_whitespace().collect::<Vec<_>>().join(" ");
            if !name.eq_ignore_ascii_case(key) {
                return Err(ImportError::BvhSyntax {
                    line: n,
                    detail: format!("expected '{key}:', found '{}'", short(trimmed)),
                });
            }
            return Ok((n, value.trim().to_owned()));
        }
        Err(ImportError::BvhSyntax { line: motion_line, detail: format!("'{key}:' is missing after MOTION") })
    };
    let (frames_line, frames) = header("Frames")?;
    let frames: u64 = frames.parse().map_err(|_| ImportError::BvhSyntax {
        line: frames_line,
        detail: format!("Frames must be a whole number, got '{}'", short(&frames)),
    })?;
    let limits = &options.limits;
    if frames > limits.max_frames as u64 {
        return Err(ImportError::TooLarge { what: "Frames", max: limits.max_frames as u64, found: frames });
    }
    let frames = frames as usize;
    let (time_line, frame_time) = header("Frame Time")?;
    let frame_time_value: f64 = frame_time.parse().unwrap_or(f64::NAN);
    if !(frame_time_value.is_finite() && frame_time_value > 0.0) {
        return Err(ImportError::BadFrameTime { value: short(&frame_time) });
    }
    if frames == 0 {
        return Err(ImportError::NoAnimations);
    }

    let width: usize = joints.iter().map(|j| j.channels.len()).sum();
    let animated: Vec<usize> = (0..joints.len()).filter(|&j| !joints[j].channels.is_empty()).collect();
    let has_rotation = |j: &Joint| j.channels.iter().any(|c| matches!(c, Dof::Rotation(_)));
    let has_position = |j: &Joint| j.channels.iter().any(|c| matches!(c, Dof::Position(_)));
    let track_count: usize =
        animated.iter().map(|&j| has_rotation(&joints[j]) as usize + has_position(&joints[j]) as usize).sum();
    if track_count > limits.max_tracks {
        return Err(ImportError::TooLarge {
            what: "the tracks of one clip",
            max: limits.max_tracks as u64,
            found: track_count as u64,
        });
    }
    let mut budget = Budget::new(limits, bytes.len());
    budget.take(joints.len())?;

    let mut rotations: Vec<Vec<Vec4>> = vec![Vec::new(); joints.len()];
    let mut translations: Vec<Vec<Vec3>> = vec![Vec::new(); joints.len()];
    let mut values: Vec<f64> = Vec::with_capacity(width);
    let mut read = 0usize;
    let mut last_line = time_line;
    for (n, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        last_line = n;
        if read == frames {
            return Err(ImportError::CountMismatch {
                line: n,
                detail: format!("Frames says {frames}, but there are more data lines"),
            });
        }
        values.clear();
        for word in line.split_ascii_whitespace() {
            if values.len() == width {
                values.push(0.0);
                break;
            }
            let v: f64 = word.parse().map_err(|_| ImportError::BvhSyntax {
                line: n,
                detail: format!("'{}' is not a number", short(word)),
            })?;
            if !v.is_finite() || !(v as f32).is_finite() {
                return Err(ImportError::NonFinite { what: format!("line {n} value {}", values.len() + 1) });
            }
            values.push(v);
        }
        if values.len() != width {
            return Err(ImportError::CountMismatch {
                line: n,
                detail: format!(
                    "frame {read} has {} values, the CHANNELS declare {width}",
                    if values.len() > width { "more".to_owned() } else { values.len().to_string() }
                ),
            });
        }
        budget.take(track_count)?;
        let mut at = 0;
        for &j in &animated {
            let joint = &joints[j];
            let mut t = joint.offset.unwrap_or(DVec3::ZERO);
            let mut q = DQuat::IDENTITY;
            for dof in &joint.channels {
                let v = values[at];
                at += 1;
                match *dof {
                    Dof::Position(axis) => t[axis] = v,
                    Dof::Rotation(axis) => {
                        let r = v.to_radians();
                        q *= match axis {
                            0 => DQuat::from_rotation_x(r),
                            1 => DQuat::from_rotation_y(r),
                            _ => DQuat::from_rotation_z(r),
                        };
                    }
                }
            }
            if has_rotation(joint) {
                rotations[j].push(Vec4::from(q.normalize().as_quat()));
            }
            if has_position(joint) {
                translations[j].push(t.as_vec3());
            }
        }
        read += 1;
    }
    if read < frames {
        return Err(ImportError::CountMismatch {
            line: last_line,
            detail: format!("Frames says {frames}, but the file ends after {read} data lines"),
        });
    }

    let times: Vec<f32> = (0..frames).map(|k| (k as f64 * frame_time_value) as f32).collect();
    // A frame time so small (or large) that f32 seconds cannot tell the
    // frames apart (or hold the last one) is as useless as zero.
    if times.windows(2).any(|w| w[1] <= w[0]) || !times.last().is_some_and(|t| t.is_finite()) {
        return Err(ImportError::BadFrameTime { value: short(&frame_time) });
    }
    let mut tracks = Vec::with_capacity(track_count);
    for &j in &animated {
        let name = &joints[j].name;
        if !translations[j].is_empty() {
            let keys = Keys::Vec3(std::mem::take(&mut translations[j]));
            tracks.push(TrackSpec::new(name, Channel::Translation, interpolation, times.clone(), keys));
        }
        if !rotations[j].is_empty() {
            let keys = Keys::Vec4(std::mem::take(&mut rotations[j]));
            tracks.push(TrackSpec::new(name, Channel::Rotation, interpolation, times.clone(), keys));
        }
    }
    let skeleton = SkeletonSpec {
        joints: joints
            .iter()
            .map(|j| JointSpec {
                name: j.name.clone(),
                parent: j.parent.map(|p| joints[p].name.clone()),
                rest: Transform { translation: j.offset.unwrap_or(DVec3::ZERO).as_vec3(), ..Transform::IDENTITY },
                inverse_bind: None,
            })
            .collect(),
    };
    let name = clip_name(options.name.as_deref().unwrap_or("bvh"));
    let clip = ClipSpec { name, skeleton: Some(skeleton), tracks, events: Vec::new(), playback: Playback::Once };
    Ok(Imported { clips: vec![clip], skipped: Vec::new() })
}

/// At most 40 characters of `s`, for messages.
fn short(s: &str) -> String {
    let mut out: String = s.chars().take(40).collect();
    if out.len() < s.len() {
        out.push('…');
    }
    out
}

/// The HIERARCHY section: joints parents-first (the file's order).
fn parse_hierarchy(tokens: &[Tok], options: &ImportOptions) -> Result<Vec<Joint>, ImportError> {
    let limits = &options.limits;
    let syntax = |line: usize, detail: String| Err(ImportError::BvhSyntax { line, detail });
    let Some(first) = tokens.first() else {
        return syntax(1, "the file is empty or has no HIERARCHY".into());
    };
    if !first.text.eq_ignore_ascii_case("HIERARCHY") {
        return syntax(first.line, format!("expected HIERARCHY, found '{}'", short(first.text)));
    }
    let mut joints: Vec<Joint> = Vec::new();
    // Joints whose `{` is open, innermost last.
    let mut open: Vec<usize> = Vec::new();
    let mut i = 1;
    let number = |t: Option<&Tok>, line: usize| -> Result<f64, ImportError> {
        let Some(t) = t else {
            return Err(ImportError::BvhSyntax { line, detail: "the file ends inside the HIERARCHY".into() });
        };
        let v: f64 = t.text.parse().map_err(|_| ImportError::BvhSyntax {
            line: t.line,
            detail: format!("expected a number, found '{}'", short(t.text)),
        })?;
        if !v.is_finite() || !(v as f32).is_finite() {
            return Err(ImportError::NonFinite { what: format!("line {} OFFSET value", t.line) });
        }
        Ok(v)
    };
    while i < tokens.len() {
        let tok = tokens[i];
        let word = tok.text;
        i += 1;
        if word.eq_ignore_ascii_case("ROOT") || word.eq_ignore_ascii_case("JOINT") || word.eq_ignore_ascii_case("End") {
            let root = word.eq_ignore_ascii_case("ROOT");
            let end_site = word.eq_ignore_ascii_case("End");
            if root != open.is_empty() {
                return syntax(
                    tok.line,
                    format!("{word} {}", if root { "inside a joint" } else { "outside any ROOT" }),
                );
            }
            let parent = open.last().copied();
            let name = if end_site {
                match tokens.get(i) {
                    Some(t) if t.text.eq_ignore_ascii_case("Site") => i += 1,
                    _ => return syntax(tok.line, "expected 'End Site'".into()),
                }
                let p = parent.map_or("root", |p| joints[p].name.as_str());
                format!("{p}_end")
            } else {
                // The name is the rest of the line (names may hold spaces).
                let mut words = Vec::new();
                while let Some(t) = tokens.get(i).filter(|t| t.line == tok.line && t.text != "{") {
                    words.push(t.text);
                    i += 1;
                }
                if words.is_empty() {
                    return syntax(tok.line, format!("{word} has no name"));
                }
                words.join(" ")
            };
            match tokens.get(i) {
                Some(t) if t.text == "{" => i += 1,
                Some(t) => return syntax(t.line, format!("expected '{{', found '{}'", short(t.text))),
                None => return syntax(tok.line, "the file ends inside the HIERARCHY".into()),
            }
            if joints.len() >= limits.max_joints {
                return Err(ImportError::TooLarge {
                    what: "the joints of one clip",
                    max: limits.max_joints as u64,
                    found: joints.len() as u64 + 1,
                });
            }
            if open.len() >= limits.max_depth {
                return Err(ImportError::TooDeep { max: limits.max_depth });
            }
            joints.push(Joint { name, parent, offset: None, channels: Vec::new(), end_site });
            open.push(joints.len() - 1);
        } else if word == "}" {
            if open.pop().is_none() {
                return syntax(tok.line, "'}' without a matching '{'".into());
            }
        } else if word.eq_ignore_ascii_case("OFFSET") {
            let Some(&j) = open.last() else { return syntax(tok.line, "OFFSET outside a joint".into()) };
            if joints[j].offset.is_some() {
                return syntax(tok.line, format!("joint '{}' has two OFFSETs", joints[j].name));
            }
            let x = number(tokens.get(i), tok.line)?;
            let y = number(tokens.get(i + 1), tok.line)?;
            let z = number(tokens.get(i + 2), tok.line)?;
            i += 3;
            joints[j].offset = Some(DVec3::new(x, y, z));
        } else if word.eq_ignore_ascii_case("CHANNELS") {
            let Some(&j) = open.last() else { return syntax(tok.line, "CHANNELS outside a joint".into()) };
            if joints[j].end_site {
                return syntax(tok.line, "an End Site cannot have CHANNELS".into());
            }
            if !joints[j].channels.is_empty() {
                return syntax(tok.line, format!("joint '{}' has two CHANNELS lines", joints[j].name));
            }
            let count = match tokens.get(i).map(|t| t.text.parse::<usize>()) {
                Some(Ok(n)) if n <= 6 => n,
                _ => return syntax(tok.line, "CHANNELS must be followed by a count from 0 to 6".into()),
            };
            i += 1;
            for _ in 0..count {
                let Some(t) = tokens.get(i) else {
                    return syntax(tok.line, "the file ends inside CHANNELS".into());
                };
                i += 1;
                let dof = match t.text.to_ascii_lowercase().as_str() {
                    "xposition" => Dof::Position(0),
                    "yposition" => Dof::Position(1),
                    "zposition" => Dof::Position(2),
                    "xrotation" => Dof::Rotation(0),
                    "yrotation" => Dof::Rotation(1),
                    "zrotation" => Dof::Rotation(2),
                    _ => {
                        return Err(ImportError::CountMismatch {
                            line: t.line,
                            detail: format!("CHANNELS declares {count}, but '{}' is not a channel name", short(t.text)),
                        });
                    }
                };
                if joints[j].channels.contains(&dof) {
                    return syntax(t.line, format!("channel '{}' is listed twice", t.text));
                }
                joints[j].channels.push(dof);
            }
            if let Some(t) = tokens.get(i).filter(|t| t.line == tok.line) {
                return Err(ImportError::CountMismatch {
                    line: t.line,
                    detail: format!("CHANNELS declares {count}, but more follow ('{}')", short(t.text)),
                });
            }
        } else {
            return syntax(tok.line, format!("unexpected '{}'", short(word)));
        }
    }
    if !open.is_empty() {
        return syntax(tokens.last().map_or(1, |t| t.line), "a joint's '{' is never closed before MOTION".into());
    }
    if joints.is_empty() {
        return syntax(first.line, "the HIERARCHY has no ROOT".into());
    }
    let names = unique_names(joints.iter_mut().map(|j| std::mem::take(&mut j.name)).collect());
    for (joint, name) in joints.iter_mut().zip(names) {
        joint.name = name;
    }
    Ok(joints)
}
