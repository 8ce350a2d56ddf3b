//! `sac-lsp render`: episodes of a checkpoint's policy as a video — an animated GIF, or MP4 through
//! ffmpeg when it is installed — and optionally one frame as a PNG, drawn headless on the CPU from
//! MuJoCo's scene with a camera that follows the ant (`sim::render`).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use anyhow::{Context, Result, anyhow, bail};
use clap::Args;
use learner::{prepare_latent, run_episode_watched};
use sim::render::{Image, Renderer, View};

use crate::policy::{Loaded, PolicyArgs};
use crate::progress::Progress;

/// Options of `sac-lsp render`.
#[derive(Debug, Args)]
#[command(
    after_help = "Example:\n  sac-lsp render --checkpoint runs/ID/checkpoints/learner-000000090000.safetensors \\\n      --task ant-v5 --latent zero --out ant.gif --still ant.png"
)]
pub struct RenderArgs {
    /// The policy.
    #[command(flatten)]
    pub policy: PolicyArgs,
    /// The video: `.gif`, or `.mp4` (needs `ffmpeg` on PATH).
    #[arg(long)]
    pub out: PathBuf,
    /// Also write the middle frame of the video as a PNG picture.
    #[arg(long, value_name = "FILE")]
    pub still: Option<PathBuf>,
    /// Episodes to record, one after another (episode i resets with seed + i).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub episodes: u32,
    /// Env steps of each episode to record (the episode itself runs to its end).
    #[arg(long, default_value_t = 400, value_parser = clap::value_parser!(u32).range(1..))]
    pub steps: u32,
    /// Draw every Nth env step (the Ant's step is 0.05 s: 1 plays at 20 frames/s, real time).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub every: u32,
    /// Picture width, pixels.
    #[arg(long, default_value_t = View::default().width)]
    pub width: u32,
    /// Picture height, pixels.
    #[arg(long, default_value_t = View::default().height)]
    pub height: u32,
    /// Camera distance from the torso, metres.
    #[arg(long, default_value_t = View::default().distance)]
    pub distance: f64,
    /// Camera azimuth, degrees.
    #[arg(long, default_value_t = View::default().azimuth, allow_negative_numbers = true)]
    pub azimuth: f64,
    /// Camera elevation, degrees (negative looks down).
    #[arg(long, default_value_t = View::default().elevation, allow_negative_numbers = true)]
    pub elevation: f64,
}

/// The video formats, by file extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Format {
    Gif,
    Mp4,
}

impl Format {
    fn of(path: &Path) -> Result<Format> {
        match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
            Some("gif") => Ok(Format::Gif),
            Some("mp4") => Ok(Format::Mp4),
            _ => bail!("--out {}: the video must end in .gif or .mp4", path.display()),
        }
    }
}

/// The program that encodes `.mp4` videos, looked up on PATH.
const FFMPEG: &str = "ffmpeg";

/// Runs `sac-lsp render`.
pub fn run(args: &RenderArgs) -> Result<()> {
    run_with(args, FFMPEG)
}

/// [`run`], encoding an `.mp4` with `ffmpeg` (the tests name one that is missing).
fn run_with(args: &RenderArgs, ffmpeg: &str) -> Result<()> {
    let format = Format::of(&args.out)?;
    if format == Format::Mp4 {
        // Before the policy is loaded or a frame drawn, which can take minutes.
        check_ffmpeg(ffmpeg).with_context(|| format!("--out {}", args.out.display()))?;
    }
    let Loaded { task, her, policy } = args.policy.load()?;
    let seed = args.policy.seed;
    let mut env = sim::her::make(&her, task, seed)?;
    let physics = env.physics().ok_or_else(|| anyhow!("{task} has no simulation to draw"))?;
    let view = View {
        width: args.width,
        height: args.height,
        distance: args.distance,
        azimuth: args.azimuth,
        elevation: args.elevation,
        ..View::default()
    };
    let mut renderer = Renderer::new(physics, view)?;
    let mut actor = policy.actor(seed)?;
    actor.load(&policy.snapshot)?;
    let mode = prepare_latent(&mut actor, args.policy.latent.mode());
    let frame_s = env.spec().dt * f64::from(args.every);

    let mut frames: Vec<Image> = Vec::new();
    // At most this many frames: an episode that ends sooner leaves the bar short.
    let per_episode = args.steps.div_ceil(args.every);
    let mut progress = Progress::new("frames", u64::from(args.episodes * per_episode));
    for i in 0..args.episodes {
        let mut step = 0u32;
        let before = frames.len();
        let episode = run_episode_watched(
            &mut actor,
            env.as_mut(),
            mode,
            Some(seed.wrapping_add(u64::from(i))),
            &mut |env| {
                if step < args.steps && step.is_multiple_of(args.every) {
                    // The environment is the one made above: it has physics.
                    if let Some(physics) = env.physics() {
                        frames.push(renderer.frame(physics));
                        progress.inc(&format!("episode {}", i + 1));
                    }
                }
                step += 1;
            },
        )?;
        eprintln!(
            "render: episode {}/{}: return {:.1} over {} steps; {} frames",
            i + 1,
            args.episodes,
            episode.episode_return,
            episode.length,
            frames.len() - before
        );
    }
    progress.finish();
    let video = match format {
        Format::Gif => gif(&frames, frame_s)?,
        Format::Mp4 => mp4(ffmpeg, &frames, frame_s)?,
    };
    node::durable::write(&args.out, &video)?;
    eprintln!(
        "render: {} frames, {:.1} s, to {}",
        frames.len(),
        frames.len() as f64 * frame_s,
        args.out.display()
    );
    if let Some(still) = &args.still {
        let frame = &frames[frames.len() / 2];
        node::durable::write(still, &crate::picture::png(frame.width, frame.height, &frame.rgb)?)?;
        eprintln!("render: frame {} to {}", frames.len() / 2, still.display());
    }
    Ok(())
}

/// An animated GIF that loops, each frame quantised to its own 256-colour palette.
fn gif(frames: &[Image], frame_s: f64) -> Result<Vec<u8>> {
    let first = frames.first().context("no frames")?;
    let (w, h) = (u16::try_from(first.width)?, u16::try_from(first.height)?);
    let mut out = Vec::new();
    {
        let mut encoder = gif::Encoder::new(&mut out, w, h, &[])?;
        encoder.set_repeat(gif::Repeat::Infinite)?;
        // GIF delays are in hundredths of a second.
        let delay = ((frame_s * 100.0).round() as u16).max(2);
        for image in frames {
            // Speed 10 of 1..30: NeuQuant's default trade of palette quality for time.
            let mut frame = gif::Frame::from_rgb_speed(w, h, &image.rgb, 10);
            frame.delay = delay;
            encoder.write_frame(&frame)?;
        }
    }
    Ok(out)
}

/// Fails, saying what to do, unless `ffmpeg` runs and has the H.264 encoder [`mp4`] uses.
fn check_ffmpeg(ffmpeg: &str) -> Result<()> {
    let encoders = match Command::new(ffmpeg)
        .args(["-hide_banner", "-loglevel", "error", "-encoders"])
        .stdin(Stdio::null())
        .output()
    {
        Ok(output) => output,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => bail!(
            "an .mp4 is encoded by {ffmpeg}, which is not on PATH: install it (Debian: apt-get install \
             ffmpeg, which deploy/setup.sh runs as root) or write a .gif, which needs nothing else"
        ),
        Err(e) => bail!("an .mp4 is encoded by {ffmpeg}, which did not run ({e}); or write a .gif"),
    };
    if !encoders.status.success() {
        bail!(
            "`{ffmpeg} -encoders` failed ({}): {}; an .mp4 needs a working ffmpeg, or write a .gif",
            encoders.status,
            String::from_utf8_lossy(&encoders.stderr).trim()
        );
    }
    if !String::from_utf8_lossy(&encoders.stdout).contains(" libx264 ") {
        bail!(
            "{ffmpeg} has no libx264 (H.264) encoder, which an .mp4 needs: install an ffmpeg built with it \
             (Debian's is) or write a .gif"
        );
    }
    Ok(())
}

/// An H.264 MP4 made by piping raw frames through `ffmpeg` (odd sizes padded by a pixel).
fn mp4(ffmpeg: &str, frames: &[Image], frame_s: f64) -> Result<Vec<u8>> {
    let first = frames.first().context("no frames")?;
    let dir = tempfile::tempdir()?;
    let (path, log) = (dir.path().join("video.mp4"), dir.path().join("ffmpeg.log"));
    // Its messages go to a file, not a pipe nobody reads while the frames are written.
    let mut child = Command::new(ffmpeg)
        .args(["-loglevel", "error", "-y", "-f", "rawvideo", "-pix_fmt", "rgb24"])
        .args(["-s", &format!("{}x{}", first.width, first.height)])
        .args(["-r", &format!("{}", 1.0 / frame_s), "-i", "-"])
        .args(["-c:v", "libx264", "-pix_fmt", "yuv420p", "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2"])
        .arg(&path)
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&log).context("ffmpeg's log file")?)
        .spawn()
        .with_context(|| format!("running {ffmpeg}"))?;
    let mut stdin = child.stdin.take().context("ffmpeg's stdin")?;
    // A write fails when ffmpeg has stopped; its log then says why.
    let written = frames.iter().try_for_each(|image| stdin.write_all(&image.rgb));
    drop(stdin);
    let status = child.wait().with_context(|| format!("waiting for {ffmpeg}"))?;
    if !status.success() || written.is_err() {
        let log = std::fs::read_to_string(&log).unwrap_or_default();
        let frames = written.err().map(|e| format!(", taking the frames: {e}")).unwrap_or_default();
        bail!("{ffmpeg} failed ({status}{frames}): {}", log.trim());
    }
    std::fs::read(&path).with_context(|| format!("reading ffmpeg's {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::policy::Latent;
    use crate::policy::tests::{checkpoint, policy_args};

    #[test]
    fn renders_a_policy_to_a_gif_and_a_png() {
        let path = checkpoint("render", false);
        let dir = path.parent().unwrap().to_path_buf();
        let args = RenderArgs {
            policy: policy_args(&path, Latent::Zero),
            out: dir.join("pendulum.gif"),
            still: Some(dir.join("pendulum.png")),
            episodes: 2,
            steps: 5,
            every: 2,
            width: 48,
            height: 32,
            distance: 3.0,
            azimuth: 90.0,
            elevation: -10.0,
        };
        run(&args).unwrap();
        let video = std::fs::read(&args.out).unwrap();
        assert_eq!(&video[..6], b"GIF89a");
        let mut decoder = gif::DecodeOptions::new().read_info(&video[..]).unwrap();
        let mut frames = 0;
        while let Some(frame) = decoder.read_next_frame().unwrap() {
            assert_eq!((frame.width, frame.height), (48, 32));
            frames += 1;
        }
        // Steps 0, 2, 4 of each episode (step 0 is the reset), unless an episode ended sooner.
        assert!((2..=6).contains(&frames), "{frames} frames");
        let still =
            png::Decoder::new(std::io::Cursor::new(std::fs::read(args.still.as_ref().unwrap()).unwrap()));
        let info = still.read_info().unwrap().info().clone();
        assert_eq!((info.width, info.height), (48, 32));

        let bad = RenderArgs { out: dir.join("pendulum.avi"), ..args };
        assert!(run(&bad).unwrap_err().to_string().contains(".gif or .mp4"));
    }

    /// Options of a short pendulum video into `out`, `width` × 32 pixels.
    fn short(checkpoint: &Path, out: PathBuf, width: u32) -> RenderArgs {
        RenderArgs {
            policy: policy_args(checkpoint, Latent::Zero),
            out,
            still: None,
            episodes: 2,
            steps: 5,
            every: 2,
            width,
            height: 32,
            distance: 3.0,
            azimuth: 90.0,
            elevation: -10.0,
        }
    }

    #[test]
    fn an_mp4_without_ffmpeg_fails_at_once_saying_why() {
        let dir = tempfile::tempdir().unwrap();
        // No checkpoint either: the check comes before anything is loaded or drawn.
        let args = short(&dir.path().join("missing.safetensors"), dir.path().join("ant.mp4"), 48);
        let err = format!("{:#}", run_with(&args, "sac-lsp-test-no-such-ffmpeg").unwrap_err());
        assert!(err.contains("ant.mp4"), "{err}");
        assert!(err.contains("sac-lsp-test-no-such-ffmpeg, which is not on PATH"), "{err}");
        assert!(err.contains("apt-get install ffmpeg") && err.contains("write a .gif"), "{err}");
        assert!(!args.out.exists());
    }

    #[test]
    fn renders_a_policy_to_an_mp4_with_ffmpeg() {
        if let Err(e) = Command::new(FFMPEG).arg("-version").stdout(Stdio::null()).status() {
            // Written past the test harness's capture, so that a run without ffmpeg shows it.
            // CI installs ffmpeg (deploy/setup.sh) and says so: there, a skip would hide the path.
            assert_ne!(
                std::env::var("SACLSP_REQUIRE_FFMPEG").as_deref(),
                Ok("1"),
                "SACLSP_REQUIRE_FFMPEG=1 but ffmpeg is not found ({e})"
            );
            let _ = writeln!(std::io::stderr(), "skipped: ffmpeg not found ({e}); the .mp4 path is untested");
            return;
        }
        let path = checkpoint("render-mp4", false);
        // An odd width, which H.264's 4:2:0 pictures cannot have: ffmpeg pads it to 48.
        let args = short(&path, path.parent().unwrap().join("pendulum.mp4"), 47);
        run(&args).unwrap();
        let video = std::fs::read(&args.out).unwrap();
        assert_eq!(&video[4..8], b"ftyp", "an MP4 starts with its ftyp box");
        // Decoded back to RGB: whole 48 × 32 frames, as many as were drawn.
        let decoded = Command::new(FFMPEG)
            .args(["-loglevel", "error", "-i"])
            .arg(&args.out)
            .args(["-f", "rawvideo", "-pix_fmt", "rgb24", "-"])
            .output()
            .unwrap();
        assert!(decoded.status.success(), "{}", String::from_utf8_lossy(&decoded.stderr));
        let frame_bytes = 48 * 32 * 3;
        assert_eq!(decoded.stdout.len() % frame_bytes, 0, "{} bytes", decoded.stdout.len());
        let frames = decoded.stdout.len() / frame_bytes;
        assert!((2..=6).contains(&frames), "{frames} frames");
    }
}
