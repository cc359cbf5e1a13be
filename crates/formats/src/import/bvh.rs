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

use super::budget::Budget;
use super::error::ImportError;
use super::names::{clip_name, unique_names};
use super::spec::{ImportLimits, ImportOptions, Imported, ImportedCharacter};
use super::warning::Warning;
use anim::lint;
use anim::{Channel, ClipSpec, Interpolation, JointSpec, Keys, Playback, SkeletonSpec, TrackSpec, Transform};

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

impl Joint {
    fn has_rotation(&self) -> bool {
        self.channels.iter().any(|c| matches!(c, Dof::Rotation(_)))
    }

    fn has_position(&self) -> bool {
        self.channels.iter().any(|c| matches!(c, Dof::Position(_)))
    }
}

/// A whitespace-separated token and the (1-based) line it is on.
#[derive(Clone, Copy)]
struct Tok<'s> {
    line: usize,
    text: &'s str,
}

pub fn import(bytes: &[u8], options: &ImportOptions) -> Result<Imported, ImportError> {
    let interpolation = frame_interpolation(options)?;
    let text: Cow<str> = String::from_utf8_lossy(bytes);
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    // Lines split on LF; a CR before it (or a lone CR) is whitespace.
    let mut lines = text.split('\n').enumerate().map(|(i, l)| (i + 1, l));

    let (tokens, motion_line) = hierarchy_tokens(&mut lines);
    let joints = parse_hierarchy(&tokens, options)?;
    let Some(motion_line) = motion_line else {
        return Err(syntax(tokens.last().map_or(1, |t| t.line), "no MOTION section".into()));
    };
    let header = motion_header(&mut lines, motion_line, &options.limits)?;
    let layout = Layout::new(&joints, &options.limits)?;
    let mut budget = Budget::new(&options.limits, bytes.len() as u64);
    budget.take(joints.len())?;
    let keys = read_frames(lines, &joints, &layout, &header, &mut budget)?;
    let times = frame_times(&header)?;

    let tracks = tracks(&joints, &layout, keys, &times, interpolation);
    let name = clip_name(options.name.as_deref().or(options.file_name.as_deref()).unwrap_or("bvh"));
    let clip = ClipSpec {
        name,
        skeleton: Some(skeleton(&joints)),
        tracks,
        events: Vec::new(),
        playback: Playback::Once,
        ..Default::default()
    };
    // The importer computes every rotation itself, so only the times can look wrong.
    let warnings = lint::times(&clip).map(|l| Warning::from_lint(&l, FRAME_TIME_POINTER)).into_iter().collect();
    let characters = if options.characters_only { vec![character(&clip)] } else { Vec::new() };
    Ok(Imported { clips: vec![clip], meshes: vec![None], springs: vec![Vec::new()], characters, warnings })
}

/// The hierarchy as a character: the offsets unrotated, each root where
/// the first frame puts it (a BVH root's OFFSET is usually 0, its height
/// in the motion).
fn character(clip: &ClipSpec) -> ImportedCharacter {
    let mut skeleton = clip.skeleton.clone().unwrap_or_default();
    for joint in skeleton.joints.iter_mut().filter(|j| j.parent.is_none()) {
        let first = clip.tracks.iter().find(|t| t.joint == joint.name && t.channel == Channel::Translation);
        if let Some(Keys::Vec3(values)) = first.map(|t| &t.values)
            && let Some(&at) = values.first()
        {
            joint.rest.translation = at;
        }
    }
    ImportedCharacter { name: clip.name.clone(), skeleton, mesh: None, roles: Default::default() }
}

/// Where a BVH warning about key times points: the header line that set
/// them (a BVH is not JSON; its pointers name its sections and keywords).
pub const FRAME_TIME_POINTER: &str = "/MOTION/Frame Time";

/// The interpolation of the frames' keys: refused before any parsing when
/// it needs tangents, which a BVH does not have.
fn frame_interpolation(options: &ImportOptions) -> Result<Interpolation, ImportError> {
    match options.bvh_interpolation {
        i @ (Interpolation::Linear | Interpolation::CatmullRom | Interpolation::BSpline | Interpolation::Step) => Ok(i),
        Interpolation::CubicHermite => {
            Err(ImportError::Unsupported("BVH frames cannot be imported as cubic_hermite (no tangents)".into()))
        }
    }
}

/// A syntax error at `line` (`bvh_syntax`).
fn syntax(line: usize, detail: String) -> ImportError {
    ImportError::BvhSyntax { line, detail }
}

/// At most 40 characters of `s`, for messages.
fn short(s: &str) -> String {
    let mut out: String = s.chars().take(40).collect();
    if out.len() < s.len() {
        out.push('…');
    }
    out
}

/// Splits the HIERARCHY into tokens, up to the MOTION line, whose number is
/// returned if there is one; `lines` is left just after it.
fn hierarchy_tokens<'s>(lines: &mut impl Iterator<Item = (usize, &'s str)>) -> (Vec<Tok<'s>>, Option<usize>) {
    let mut tokens: Vec<Tok> = Vec::new();
    for (n, line) in lines {
        let mut words = line.split_ascii_whitespace().peekable();
        if words.peek().is_some_and(|w| w.eq_ignore_ascii_case("MOTION")) {
            return (tokens, Some(n));
        }
        tokens.extend(words.map(|text| Tok { line: n, text }));
    }
    (tokens, None)
}

/// The MOTION header, checked before any frame is read.
struct MotionHeader {
    frames: usize,
    /// Seconds per frame: finite and positive.
    frame_time: f64,
    /// The frame time as written, for messages.
    frame_time_text: String,
    /// The `Frame Time:` line, where a file without frames is reported.
    line: usize,
}

/// Reads `Frames: N` and `Frame Time: x` and checks them against the limits.
fn motion_header<'s>(
    lines: &mut impl Iterator<Item = (usize, &'s str)>,
    motion_line: usize,
    limits: &ImportLimits,
) -> Result<MotionHeader, ImportError> {
    let (frames_line, frames) = header_line(lines, motion_line, "Frames")?;
    let frames: u64 = frames
        .parse()
        .map_err(|_| syntax(frames_line, format!("Frames must be a whole number, got '{}'", short(&frames))))?;
    if frames > limits.max_frames as u64 {
        return Err(ImportError::TooLarge { what: "Frames", max: limits.max_frames as u64, found: frames });
    }
    let (line, frame_time_text) = header_line(lines, motion_line, "Frame Time")?;
    let frame_time: f64 = frame_time_text.parse().unwrap_or(f64::NAN);
    if !(frame_time.is_finite() && frame_time > 0.0) {
        return Err(ImportError::BadFrameTime { value: short(&frame_time_text) });
    }
    if frames == 0 {
        return Err(ImportError::NoAnimations);
    }
    Ok(MotionHeader { frames: frames as usize, frame_time, frame_time_text, line })
}

/// The next non-blank line, which must be `key: value`: its number and value.
fn header_line<'s>(
    lines: &mut impl Iterator<Item = (usize, &'s str)>,
    motion_line: usize,
    key: &str,
) -> Result<(usize, String), ImportError> {
    for (n, line) in lines {
        let trimmed = line.trim();
        if trimmed.is_empty() {
            continue;
        }
        let (name, value) = trimmed.split_once(':').unwrap_or((trimmed, ""));
        let name: String = name.split_ascii_whitespace().collect::<Vec<_>>().join(" ");
        if !name.eq_ignore_ascii_case(key) {
            return Err(syntax(n, format!("expected '{key}:', found '{}'", short(trimmed))));
        }
        return Ok((n, value.trim().to_owned()));
    }
    Err(syntax(motion_line, format!("'{key}:' is missing after MOTION")))
}

/// How one frame's values map to joints, with the track count checked
/// against the limit before any key is read.
struct Layout {
    /// Values per frame line: every joint's channels, in file order.
    width: usize,
    /// The joints that have channels.
    animated: Vec<usize>,
    /// A translation track per joint with position channels, a rotation
    /// track per joint with rotation channels.
    track_count: usize,
}

impl Layout {
    fn new(joints: &[Joint], limits: &ImportLimits) -> Result<Layout, ImportError> {
        let width: usize = joints.iter().map(|j| j.channels.len()).sum();
        let animated: Vec<usize> = (0..joints.len()).filter(|&j| !joints[j].channels.is_empty()).collect();
        let track_count: usize =
            animated.iter().map(|&j| joints[j].has_rotation() as usize + joints[j].has_position() as usize).sum();
        if track_count > limits.max_tracks {
            return Err(ImportError::TooLarge {
                what: "the tracks of one clip",
                max: limits.max_tracks as u64,
                found: track_count as u64,
            });
        }
        Ok(Layout { width, animated, track_count })
    }
}

/// Every frame's keys, per joint (empty for a joint without that channel).
struct FrameKeys {
    rotations: Vec<Vec<Vec4>>,
    translations: Vec<Vec<Vec3>>,
}

/// Reads the frame lines, one key per animated channel each, checking
/// their number against `Frames:` and each line's width against CHANNELS.
fn read_frames<'s>(
    lines: impl Iterator<Item = (usize, &'s str)>,
    joints: &[Joint],
    layout: &Layout,
    header: &MotionHeader,
    budget: &mut Budget,
) -> Result<FrameKeys, ImportError> {
    let frames = header.frames;
    let mut keys =
        FrameKeys { rotations: vec![Vec::new(); joints.len()], translations: vec![Vec::new(); joints.len()] };
    let mut values: Vec<f64> = Vec::with_capacity(layout.width);
    let mut read = 0usize;
    let mut last_line = header.line;
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
        frame_values(line, n, read, layout.width, &mut values)?;
        budget.take(layout.track_count)?;
        keys.push_frame(joints, &layout.animated, &values);
        read += 1;
    }
    if read < frames {
        return Err(ImportError::CountMismatch {
            line: last_line,
            detail: format!("Frames says {frames}, but the file ends after {read} data lines"),
        });
    }
    Ok(keys)
}

/// Parses frame `frame` (line `n`) into `values`: exactly `width` finite
/// numbers, or an error naming the first that is not.
fn frame_values(line: &str, n: usize, frame: usize, width: usize, values: &mut Vec<f64>) -> Result<(), ImportError> {
    values.clear();
    for word in line.split_ascii_whitespace() {
        if values.len() == width {
            values.push(0.0);
            break;
        }
        let v: f64 = word.parse().map_err(|_| syntax(n, format!("'{}' is not a number", short(word))))?;
        if !v.is_finite() || !(v as f32).is_finite() {
            return Err(ImportError::NonFinite { what: format!("line {n} value {}", values.len() + 1) });
        }
        values.push(v);
    }
    if values.len() != width {
        return Err(ImportError::CountMismatch {
            line: n,
            detail: format!(
                "frame {frame} has {} values, the CHANNELS declare {width}",
                if values.len() > width { "more".to_owned() } else { values.len().to_string() }
            ),
        });
    }
    Ok(())
}

impl FrameKeys {
    /// Appends one frame: each animated joint's channels, in order, taken
    /// from `values` (as wide as the layout).
    fn push_frame(&mut self, joints: &[Joint], animated: &[usize], values: &[f64]) {
        let mut at = 0;
        for &j in animated {
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
            if joint.has_rotation() {
                self.rotations[j].push(Vec4::from(q.normalize().as_quat()));
            }
            if joint.has_position() {
                self.translations[j].push(t.as_vec3());
            }
        }
    }
}

/// Frame `k` at `k · Frame Time`, in f32 seconds.
fn frame_times(header: &MotionHeader) -> Result<Vec<f32>, ImportError> {
    let times: Vec<f32> = (0..header.frames).map(|k| (k as f64 * header.frame_time) as f32).collect();
    // A frame time so small (or large) that f32 seconds cannot tell the
    // frames apart (or hold the last one) is as useless as zero.
    if times.windows(2).any(|w| w[1] <= w[0]) || !times.last().is_some_and(|t| t.is_finite()) {
        return Err(ImportError::BadFrameTime { value: short(&header.frame_time_text) });
    }
    Ok(times)
}

/// The clip's tracks: per animated joint, translation then rotation.
fn tracks(
    joints: &[Joint],
    layout: &Layout,
    mut keys: FrameKeys,
    times: &[f32],
    interpolation: Interpolation,
) -> Vec<TrackSpec> {
    let mut tracks = Vec::with_capacity(layout.track_count);
    for &j in &layout.animated {
        let name = &joints[j].name;
        if !keys.translations[j].is_empty() {
            let values = Keys::Vec3(std::mem::take(&mut keys.translations[j]));
            tracks.push(TrackSpec::new(name, Channel::Translation, interpolation, times.to_vec(), values));
        }
        if !keys.rotations[j].is_empty() {
            let values = Keys::Vec4(std::mem::take(&mut keys.rotations[j]));
            tracks.push(TrackSpec::new(name, Channel::Rotation, interpolation, times.to_vec(), values));
        }
    }
    tracks
}

/// The skeleton: every joint in file order, its OFFSET as rest translation.
fn skeleton(joints: &[Joint]) -> SkeletonSpec {
    SkeletonSpec {
        joints: joints
            .iter()
            .map(|j| JointSpec {
                name: j.name.clone(),
                parent: j.parent.map(|p| joints[p].name.clone()),
                rest: Transform { translation: j.offset.unwrap_or(DVec3::ZERO).as_vec3(), ..Transform::IDENTITY },
                inverse_bind: None,
            })
            .collect(),
    }
}

/// The HIERARCHY section: joints parents-first (the file's order).
fn parse_hierarchy(tokens: &[Tok], options: &ImportOptions) -> Result<Vec<Joint>, ImportError> {
    let Some(first) = tokens.first() else {
        return Err(syntax(1, "the file is empty or has no HIERARCHY".into()));
    };
    if !first.text.eq_ignore_ascii_case("HIERARCHY") {
        return Err(syntax(first.line, format!("expected HIERARCHY, found '{}'", short(first.text))));
    }
    let mut parser = Hierarchy { tokens, at: 1, joints: Vec::new(), open: Vec::new(), limits: &options.limits };
    while let Some(&tok) = tokens.get(parser.at) {
        parser.at += 1;
        let word = tok.text;
        if word.eq_ignore_ascii_case("ROOT") || word.eq_ignore_ascii_case("JOINT") || word.eq_ignore_ascii_case("End") {
            parser.joint(tok)?;
        } else if word == "}" {
            if parser.open.pop().is_none() {
                return Err(syntax(tok.line, "'}' without a matching '{'".into()));
            }
        } else if word.eq_ignore_ascii_case("OFFSET") {
            parser.offset(tok)?;
        } else if word.eq_ignore_ascii_case("CHANNELS") {
            parser.channels(tok)?;
        } else {
            return Err(syntax(tok.line, format!("unexpected '{}'", short(word))));
        }
    }
    parser.finish(first)
}

/// The HIERARCHY parser's state: a cursor over the tokens and an explicit
/// stack of open joints (no recursion, so depth is only a limit).
struct Hierarchy<'t, 's> {
    tokens: &'t [Tok<'s>],
    /// The next token to read.
    at: usize,
    joints: Vec<Joint>,
    /// Joints whose `{` is open, innermost last.
    open: Vec<usize>,
    limits: &'t ImportLimits,
}

impl Hierarchy<'_, '_> {
    /// `ROOT <name> {`, `JOINT <name> {` or `End Site {` (the keyword is
    /// `tok`): a new joint under the innermost open one, now open itself.
    fn joint(&mut self, tok: Tok) -> Result<(), ImportError> {
        let word = tok.text;
        let root = word.eq_ignore_ascii_case("ROOT");
        let end_site = word.eq_ignore_ascii_case("End");
        if root != self.open.is_empty() {
            return Err(syntax(
                tok.line,
                format!("{word} {}", if root { "inside a joint" } else { "outside any ROOT" }),
            ));
        }
        let parent = self.open.last().copied();
        let name = if end_site { self.end_site_name(tok, parent)? } else { self.joint_name(tok)? };
        match self.tokens.get(self.at) {
            Some(t) if t.text == "{" => self.at += 1,
            Some(t) => return Err(syntax(t.line, format!("expected '{{', found '{}'", short(t.text)))),
            None => return Err(syntax(tok.line, "the file ends inside the HIERARCHY".into())),
        }
        if self.joints.len() >= self.limits.max_joints {
            return Err(ImportError::TooLarge {
                what: "the joints of one clip",
                max: self.limits.max_joints as u64,
                found: self.joints.len() as u64 + 1,
            });
        }
        if self.open.len() >= self.limits.max_depth {
            return Err(ImportError::TooDeep { max: self.limits.max_depth });
        }
        self.joints.push(Joint { name, parent, offset: None, channels: Vec::new(), end_site });
        self.open.push(self.joints.len() - 1);
        Ok(())
    }

    /// After `End`: `Site`, named `<parent>_end`.
    fn end_site_name(&mut self, tok: Tok, parent: Option<usize>) -> Result<String, ImportError> {
        match self.tokens.get(self.at) {
            Some(t) if t.text.eq_ignore_ascii_case("Site") => self.at += 1,
            _ => return Err(syntax(tok.line, "expected 'End Site'".into())),
        }
        let p = parent.map_or("root", |p| self.joints[p].name.as_str());
        Ok(format!("{p}_end"))
    }

    /// After `ROOT`/`JOINT`: the name is the rest of the line (names may
    /// hold spaces), up to a `{` on the same line.
    fn joint_name(&mut self, tok: Tok) -> Result<String, ImportError> {
        let mut words = Vec::new();
        while let Some(t) = self.tokens.get(self.at).filter(|t| t.line == tok.line && t.text != "{") {
            words.push(t.text);
            self.at += 1;
        }
        if words.is_empty() {
            return Err(syntax(tok.line, format!("{} has no name", tok.text)));
        }
        Ok(words.join(" "))
    }

    /// `OFFSET x y z` of the innermost open joint (at most one).
    fn offset(&mut self, tok: Tok) -> Result<(), ImportError> {
        let Some(&j) = self.open.last() else { return Err(syntax(tok.line, "OFFSET outside a joint".into())) };
        if self.joints[j].offset.is_some() {
            return Err(syntax(tok.line, format!("joint '{}' has two OFFSETs", self.joints[j].name)));
        }
        let x = offset_value(self.tokens.get(self.at), tok.line)?;
        let y = offset_value(self.tokens.get(self.at + 1), tok.line)?;
        let z = offset_value(self.tokens.get(self.at + 2), tok.line)?;
        self.at += 3;
        self.joints[j].offset = Some(DVec3::new(x, y, z));
        Ok(())
    }

    /// `CHANNELS n name…` of the innermost open joint: at most one line of
    /// at most six distinct channels, exactly `n` of them.
    fn channels(&mut self, tok: Tok) -> Result<(), ImportError> {
        let Some(&j) = self.open.last() else { return Err(syntax(tok.line, "CHANNELS outside a joint".into())) };
        if self.joints[j].end_site {
            return Err(syntax(tok.line, "an End Site cannot have CHANNELS".into()));
        }
        if !self.joints[j].channels.is_empty() {
            return Err(syntax(tok.line, format!("joint '{}' has two CHANNELS lines", self.joints[j].name)));
        }
        let count = match self.tokens.get(self.at).map(|t| t.text.parse::<usize>()) {
            Some(Ok(n)) if n <= 6 => n,
            _ => return Err(syntax(tok.line, "CHANNELS must be followed by a count from 0 to 6".into())),
        };
        self.at += 1;
        for _ in 0..count {
            let Some(&t) = self.tokens.get(self.at) else {
                return Err(syntax(tok.line, "the file ends inside CHANNELS".into()));
            };
            self.at += 1;
            let dof = channel_dof(t, count)?;
            if self.joints[j].channels.contains(&dof) {
                return Err(syntax(t.line, format!("channel '{}' is listed twice", t.text)));
            }
            self.joints[j].channels.push(dof);
        }
        if let Some(t) = self.tokens.get(self.at).filter(|t| t.line == tok.line) {
            return Err(ImportError::CountMismatch {
                line: t.line,
                detail: format!("CHANNELS declares {count}, but more follow ('{}')", short(t.text)),
            });
        }
        Ok(())
    }

    /// The joints, once every `{` is closed and there is at least one ROOT,
    /// with repeated names made unique.
    fn finish(mut self, first: &Tok) -> Result<Vec<Joint>, ImportError> {
        if !self.open.is_empty() {
            let line = self.tokens.last().map_or(1, |t| t.line);
            return Err(syntax(line, "a joint's '{' is never closed before MOTION".into()));
        }
        if self.joints.is_empty() {
            return Err(syntax(first.line, "the HIERARCHY has no ROOT".into()));
        }
        let names = unique_names(self.joints.iter_mut().map(|j| std::mem::take(&mut j.name)).collect());
        for (joint, name) in self.joints.iter_mut().zip(names) {
            joint.name = name;
        }
        Ok(self.joints)
    }
}

/// One OFFSET component (`line` is the OFFSET's, for a file that ends).
fn offset_value(t: Option<&Tok>, line: usize) -> Result<f64, ImportError> {
    let Some(t) = t else {
        return Err(syntax(line, "the file ends inside the HIERARCHY".into()));
    };
    let v: f64 = t.text.parse().map_err(|_| syntax(t.line, format!("expected a number, found '{}'", short(t.text))))?;
    if !v.is_finite() || !(v as f32).is_finite() {
        return Err(ImportError::NonFinite { what: format!("line {} OFFSET value", t.line) });
    }
    Ok(v)
}

/// A channel name (`Xposition` … `Zrotation`, any case); anything else
/// means the CHANNELS count and its names disagree.
fn channel_dof(t: Tok, count: usize) -> Result<Dof, ImportError> {
    Ok(match t.text.to_ascii_lowercase().as_str() {
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
    })
}
