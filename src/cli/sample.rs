//! `inbetween sample CLIP.json`: evaluate a clip file without a server.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args;
use glam::Mat4;

use anim::{Clip, SampleOptions, Sampler, frame_count, frame_times};
use formats::wire::json::{
    EaseDoc, Extras, MatricesJson, ParameterValues, PlaybackDoc, PoseJson, SpaceDoc, parse_clip,
};

/// The most poses one invocation prints.
const MAX_POSES: u64 = 1_000_000;

#[derive(Debug, Args)]
pub struct SampleArgs {
    /// A clip document (JSON, docs/clip-format.md).
    clip: PathBuf,
    /// A time to sample, in seconds (repeatable).
    #[arg(long = "t", value_name = "SECONDS", allow_negative_numbers = true, conflicts_with_all = ["start", "end", "fps"])]
    times: Vec<f64>,
    /// First time of a frame range (with --end and --fps).
    #[arg(long, requires_all = ["end", "fps"], allow_negative_numbers = true)]
    start: Option<f64>,
    #[arg(long, requires_all = ["start", "fps"], allow_negative_numbers = true)]
    end: Option<f64>,
    #[arg(long, requires_all = ["start", "end"])]
    fps: Option<f64>,
    #[arg(long, default_value = "local")]
    space: SpaceDoc,
    /// once | loop | ping_pong; the clip's own mode by default.
    #[arg(long)]
    playback: Option<PlaybackDoc>,
    #[arg(long, default_value = "linear")]
    ease: EaseDoc,
    /// trs (translation, rotation, scale per joint) or matrix (column-major
    /// model matrices) or skinning.
    #[arg(long, default_value = "trs")]
    format: String,
}

pub fn run(args: SampleArgs) -> anyhow::Result<()> {
    let body = std::fs::read(&args.clip).with_context(|| format!("reading {}", args.clip.display()))?;
    let (_, spec) =
        parse_clip(&body).map_err(|e| anyhow::anyhow!("{}: invalid clip: {e} ({})", args.clip.display(), e.code))?;
    let clip = Clip::build(&spec)
        .map_err(|e| anyhow::anyhow!("{}: invalid clip: {e} ({})", args.clip.display(), e.kind.code()))?;

    let times: Vec<f64> = match (args.start, args.end, args.fps) {
        (Some(s), Some(e), Some(f)) => {
            let n = frame_count(s, e, f);
            if n == 0 {
                bail!("--start, --end and --fps must be finite with end >= start and fps > 0");
            }
            if n > MAX_POSES {
                bail!("{n} frames requested; the limit is {MAX_POSES}");
            }
            frame_times(s, e, f).collect()
        }
        _ if args.times.is_empty() => bail!("give at least one --t, or --start/--end/--fps"),
        _ => args.times.clone(),
    };
    if let Some(t) = times.iter().find(|t| !t.is_finite()) {
        bail!("time {t} is not a finite number");
    }
    let options =
        SampleOptions { playback: args.playback.map(Into::into), ease: args.ease.into(), space: args.space.into() };
    let skinning = match args.format.as_str() {
        "trs" => None,
        "matrix" => Some(false),
        "skinning" if clip.skeleton().has_inverse_binds() => Some(true),
        "skinning" => bail!("format=skinning needs a clip with inverse bind matrices"),
        other => bail!("unknown --format {other}: expected trs, matrix or skinning"),
    };

    let mut sampler = Sampler::new();
    let mut matrices: Vec<Mat4> = Vec::new();
    let mut out = super::results::Results::buffered();
    out.write_all(b"[")?;
    for (k, &t) in times.iter().enumerate() {
        if k > 0 {
            out.write_all(b",\n")?;
        }
        match skinning {
            None => {
                let clip_time = clip.sample(t, &options, &mut sampler);
                let pose = PoseJson {
                    clip: clip.name(),
                    time: t,
                    clip_time,
                    space: options.space,
                    skeleton: clip.skeleton(),
                    pose: sampler.pose(),
                };
                let mut text = Vec::new();
                let parameters = ParameterValues::of(clip.parameters(), sampler.pose(), None);
                pose.write_with(&mut text, Extras { ik: sampler.ik_reports(), parameters, ..Extras::default() });
                out.write_all(&text)?;
            }
            Some(skin) => {
                clip.matrices(t, &options, skin, &mut sampler, &mut matrices);
                let clip_time = clip.clip_time(t, options.playback.unwrap_or(clip.playback()), options.ease);
                let format = if skin { "skinning" } else { "matrix" };
                let doc = MatricesJson {
                    clip: clip.name(),
                    time: t,
                    clip_time,
                    format,
                    skeleton: clip.skeleton(),
                    matrices: &matrices,
                };
                let mut text = Vec::new();
                let parameters = ParameterValues::of(clip.parameters(), sampler.pose(), None);
                doc.write_with(&mut text, Extras { ik: sampler.ik_reports(), parameters, ..Extras::default() });
                out.write_all(&text)?;
            }
        }
    }
    out.write_all(b"]\n")?;
    out.flush()?;
    Ok(())
}
