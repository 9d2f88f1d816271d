//! Video: a stream of HDR frames through the time course of adaptation, one frame after
//! another (Sec. 4.4 and Eq. 8–9, the mapping of [`timecourse`](crate::timecourse)), with
//! the decoding of later frames and the encoding of earlier ones overlapping the operator.
//!
//! Two parts:
//!
//! * [`Observer`] is the model's step per frame: the observer starts adapted to the first
//!   frame's world adaptation (Sec. 4.4: half its highest visible luminance, photopic and
//!   scotopic); every later frame steps the adaptation state by `1/fps` to that frame's
//!   world adaptation and is mapped with the state's Eq. 8–9 mapping
//!   ([`operator::apply_state_into`]). These are the three calls a renderer makes per
//!   frame; [`Observer`] adds the frame clock and the check that frames keep one size.
//! * [`run`] is the pipeline around it: decoder threads read frames ([`Source`]), the
//!   calling thread runs the operator on them in frame order (the state is stepped from
//!   each frame to the next, so this stage is one thread; its passes are parallel inside),
//!   and encoder threads encode the mapped frames and write them ([`Sink`]), each write in
//!   frame order. Frames are handed from stage to stage directly (no queue beyond the
//!   frame handed over), and the images go round and are reused: at most `decoders + 1`
//!   HDR frames, `encoders + 1` display images and `encoders` encoded files exist at
//!   once, whatever the length of the video. The output is the same, byte for byte, as
//!   mapping and writing one frame after another.
//!
//! On an error the frames before it are written, none after it, and the error of the
//! earliest frame is returned.
//!
//! ```
//! use visadapt::{DisplayImage, HdrImage, operator::ViewingConditions};
//! use visadapt::video::{self, Observer, Threads};
//!
//! // Frames in memory, a sink keeping the mean of each mapped frame's green plane.
//! struct Frames(Vec<f32>);
//! impl video::Source<visadapt::Error> for Frames {
//!     fn read(&self, index: u64, _: &mut Vec<u8>, image: &mut HdrImage)
//!         -> visadapt::Result<bool> {
//!         let Some(&l) = self.0.get(index as usize) else { return Ok(false) };
//!         *image = HdrImage::zeros(64, 32);
//!         image.x.fill(0.9505 * l); image.y.fill(l); image.z.fill(1.089 * l);
//!         image.absolute_units = true;
//!         Ok(true)
//!     }
//! }
//! struct Means(std::sync::Mutex<Vec<f32>>);
//! impl video::Sink<visadapt::Error> for Means {
//!     type Frame = ();
//!     fn encode(&self, _: u64, image: &DisplayImage, bytes: &mut Vec<u8>)
//!         -> visadapt::Result<()> {
//!         let mean = image.g.iter().sum::<f32>() / image.g.len() as f32;
//!         *bytes = mean.to_le_bytes().to_vec();
//!         Ok(())
//!     }
//!     fn write(&self, _: u64, bytes: &[u8], _: ()) -> visadapt::Result<()> {
//!         self.0.lock().unwrap().push(f32::from_le_bytes(bytes.try_into().unwrap()));
//!         Ok(())
//!     }
//! }
//! // A second at 1000 cd/m², then darkness falls to 0.01 cd/m² for two seconds.
//! let frames = Frames([vec![1000.0; 10], vec![0.01; 20]].concat());
//! let sink = Means(Default::default());
//! let mut eye = Observer::new(ViewingConditions::default(), 10.0)?;
//! let timings = video::run(&frames, |_, hdr: &mut HdrImage, out: &mut DisplayImage| {
//!     eye.frame(hdr, out).map(|_| ())
//! }, &sink, Threads::default())?;
//! assert_eq!(timings.frames, 30);
//! let means = sink.0.into_inner().unwrap();
//! // Just after the fall the light-adapted eye shows the dark room dimmer than it will
//! // (Eq. 8-9: a low m(t)); two seconds later it has begun to adapt and shows more.
//! assert!(means[10] < means[29] && means[29] < means[9]);
//! # Ok::<(), visadapt::Error>(())
//! ```

use crate::glare;
use crate::io::{self, OutputFormat};
use crate::local::AdaptationMap;
use crate::operator::{self, Mapping, PixelStats, Report, ViewingConditions};
use crate::timecourse::Adaptation;
use crate::{DisplayImage, Error, HdrImage, Limits, Result};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, mpsc};
use std::time::{Duration, Instant};

/// The observer of a video: the adaptation state carried from frame to frame and the
/// frame clock (frame `k` is seen at `k / fps` seconds).
#[derive(Debug, Clone)]
pub struct Observer {
    conditions: ViewingConditions,
    dt_seconds: f64,
    state: Option<Adaptation>,
    size: Option<(usize, usize)>,
    frames: u64,
    /// The adaptation map of local adaptation, its planes kept from frame to frame.
    map: AdaptationMap,
    /// The scene stages' workspace (glare), kept from frame to frame.
    scene: glare::Workspace,
}

/// What the model did with one frame.
#[derive(Debug, Clone)]
pub struct Frame {
    /// The frame's time since the first frame, seconds (`k / fps`).
    pub t_seconds: f64,
    /// The steady-state plan of the frame ([`operator::prepare`]): its world adaptation.
    pub report: Report,
    /// The Eq. 8–9 mapping of the state at this frame (what the frame was mapped with).
    pub mapping: Mapping,
    /// Pixels that needed a rule applied.
    pub stats: PixelStats,
    /// The adaptation state at this frame (thresholds, acuity).
    pub state: Adaptation,
}

impl Observer {
    /// An observer of frames shown `fps` frames per second under `conditions` (its
    /// `undershoot` rule included), not yet adapted to anything: the first frame sets the
    /// state. Refuses a frame rate that is not positive and finite, and invalid conditions.
    pub fn new(conditions: ViewingConditions, fps: f64) -> Result<Self> {
        if !(fps.is_finite() && fps > 0.0) {
            return Err(Error::invalid(
                "fps",
                fps,
                "must be a positive, finite number of frames per second",
            ));
        }
        conditions.validate()?;
        Ok(Observer {
            conditions,
            dt_seconds: 1.0 / fps,
            state: None,
            size: None,
            frames: 0,
            map: AdaptationMap::default(),
            scene: glare::Workspace::new(),
        })
    }

    /// The conditions frames are mapped under.
    pub fn conditions(&self) -> &ViewingConditions {
        &self.conditions
    }

    /// Frames seen so far.
    pub fn frames_seen(&self) -> u64 {
        self.frames
    }

    /// See the next frame and map it into `out` (its memory reused): the first frame
    /// adapts the observer to its world adaptation, every later one steps the state by
    /// `1/fps` to its own first. A frame of another size than the first is refused (the
    /// state is then unchanged).
    pub fn frame(&mut self, image: &HdrImage, out: &mut DisplayImage) -> Result<Frame> {
        let size = (image.width, image.height);
        match self.size {
            Some((w, h)) if (w, h) != size => {
                return Err(Error::invalid(
                    "frame size",
                    format!("{}x{}", size.0, size.1),
                    format!("differs from the first frame's {w}x{h}"),
                ));
            }
            _ => {}
        }
        let (scene, report) = operator::prepare_reusing(image, &self.conditions, &mut self.scene)?;
        let state = match &self.state {
            None => Adaptation::adapted(
                report.world_adaptation_cd_m2,
                report.world_adaptation_scotopic_cd_m2,
            )?
            .with_undershoot(self.conditions.undershoot),
            Some(state) => {
                let mut next = state.clone();
                next.step_to(self.dt_seconds, &report)?;
                next
            }
        };
        let (mapping, stats) = operator::apply_state_reusing(
            scene,
            &report,
            &state,
            &self.conditions,
            &mut self.map,
            out,
        )?;
        let t_seconds = self.frames as f64 * self.dt_seconds;
        self.size = Some(size);
        self.frames += 1;
        self.state = Some(state.clone());
        Ok(Frame {
            t_seconds,
            report,
            mapping,
            stats,
            state,
        })
    }
}

/// Where the frames of [`run`] come from.
pub trait Source<E>: Sync {
    /// Decode frame `index` (0, 1, 2, …) into `image`, reusing its memory and that of
    /// `bytes` (a scratch buffer owned by the calling thread, e.g. for the file's bytes).
    /// `Ok(false)`: there is no frame `index` (the video has ended).
    ///
    /// Called from several decoder threads at once, each with its own frames, in no
    /// particular order, unless [`Source::in_order`] says otherwise.
    fn read(&self, index: u64, bytes: &mut Vec<u8>, image: &mut HdrImage) -> Result<bool, E>;

    /// Whether the frames can only be read one after another (a stream): then one decoder
    /// thread reads them, in order. `false` by default.
    fn in_order(&self) -> bool {
        false
    }
}

/// Where the mapped frames of [`run`] go.
pub trait Sink<E>: Sync {
    /// What the operator stage passes on with each frame (e.g. a line of report), given
    /// to [`Sink::write`].
    type Frame: Send;

    /// Encode frame `index` into `bytes` (its previous contents replaced, its memory
    /// reused). Called from several encoder threads at once, in no particular order.
    fn encode(&self, index: u64, image: &DisplayImage, bytes: &mut Vec<u8>) -> Result<(), E>;

    /// Write the encoded frame `index` (e.g. to a file, atomically, or onto a stream).
    /// Called one frame at a time and in frame order, each frame after the one before it
    /// was written.
    fn write(&self, index: u64, bytes: &[u8], frame: Self::Frame) -> Result<(), E>;
}

/// How many threads decode and encode (the operator is one more, the calling thread).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Threads {
    /// Decoder threads (1 for a [`Source`] read in order).
    pub decoders: usize,
    /// Encoder threads.
    pub encoders: usize,
}

impl Default for Threads {
    /// One decoder per two cores the system offers and one encoder per core, from one
    /// to four each: on two cores, one decoder and two encoders. The operator's passes
    /// run on every core and the other stages fill the gaps. A PNG frame's compressor
    /// ([`PngCompression::Fdeflate`](io::display::PngCompression::Fdeflate), `video`'s default) runs on one thread, so with one
    /// encoder the frame rate was bound by encoding; two encoders took the whole process
    /// on 24 1080p frames from 0.82–0.98 s to 0.71–0.83 s (`.hdr`) and from 1.13–1.58 s
    /// to 0.97–1.24 s (`.exr`), for about 31 MiB more memory (see the README's
    /// "Performance: Video"). More decoders pay only beyond two cores, where one
    /// frame's serial parts (an EXR's channel conversion) would bound the rate.
    fn default() -> Self {
        let cores = std::thread::available_parallelism().map_or(1, usize::from);
        Threads {
            decoders: (cores / 2).clamp(1, 4),
            encoders: cores.clamp(1, 4),
        }
    }
}

/// Where the time of a [`run`] went: each stage's busy time (summed over its threads)
/// and the operator's waits, from which the stage that bounds the frame rate can be told
/// (the operator waiting for frames: decoding; waiting to hand them on: encoding).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Timings {
    /// Frames written.
    pub frames: u64,
    /// Decoder and encoder threads used.
    pub threads: (usize, usize),
    /// Wall-clock time of the whole run.
    pub wall: Duration,
    /// Time in [`Source::read`], summed over the decoder threads.
    pub decoding: Duration,
    /// Time in the operator (the `map` of [`run`]).
    pub operator: Duration,
    /// Time the operator waited for its next decoded frame.
    pub operator_waiting_for_frames: Duration,
    /// Time the operator waited for an encoder to take a frame, or for a free display
    /// image.
    pub operator_waiting_for_encoders: Duration,
    /// Time in [`Sink::encode`], summed over the encoder threads.
    pub encoding: Duration,
    /// Time in [`Sink::write`].
    pub writing: Duration,
}

impl Timings {
    /// Frames written per second of wall-clock time.
    pub fn frames_per_second(&self) -> f64 {
        self.frames as f64 / self.wall.as_secs_f64().max(f64::MIN_POSITIVE)
    }
}

/// A stage's busy time, summed over its threads, in nanoseconds.
#[derive(Default)]
struct Clock(AtomicU64);

impl Clock {
    fn time<T>(&self, f: impl FnOnce() -> T) -> T {
        let start = Instant::now();
        let out = f();
        self.add(start.elapsed());
        out
    }

    fn add(&self, d: Duration) {
        let ns = u64::try_from(d.as_nanos()).unwrap_or(u64::MAX);
        self.0.fetch_add(ns, Ordering::Relaxed);
    }

    fn get(&self) -> Duration {
        Duration::from_nanos(self.0.load(Ordering::Relaxed))
    }
}

/// Frames take turns: `wait(k)` returns once every frame before `k` has had its turn
/// (`done`), or `None` as soon as `give_up` says this frame is not to be passed on.
struct Turns {
    next: Mutex<u64>,
    changed: Condvar,
}

impl Turns {
    fn new() -> Self {
        Turns {
            next: Mutex::new(0),
            changed: Condvar::new(),
        }
    }

    fn wait(&self, index: u64, give_up: impl Fn() -> bool) -> Option<()> {
        let mut next = self.next.lock().unwrap_or_else(|e| e.into_inner());
        loop {
            // Giving up comes first: the turn may have come because an earlier frame
            // failed (an encoder's error ends its turn too).
            if give_up() {
                return None;
            }
            if *next == index {
                return Some(());
            }
            next = self.changed.wait(next).unwrap_or_else(|e| e.into_inner());
        }
    }

    /// The turn of the frame waited for is over: the next frame's begins.
    fn done(&self) {
        *self.next.lock().unwrap_or_else(|e| e.into_inner()) += 1;
        self.changed.notify_all();
    }

    /// Wake every waiter to look at its `give_up` again (after it changed).
    fn wake(&self) {
        drop(self.next.lock().unwrap_or_else(|e| e.into_inner()));
        self.changed.notify_all();
    }
}

/// Start a thread of the pipeline, named (for profilers and debuggers); a thread the
/// system cannot start is a panic, as with [`std::thread::spawn`].
fn spawn<'scope>(
    s: &'scope std::thread::Scope<'scope, '_>,
    name: &str,
    f: impl FnOnce() + Send + 'scope,
) {
    std::thread::Builder::new()
        .name(name.into())
        .spawn_scoped(s, f)
        .expect("the system starts a thread");
}

/// A frame on its way from a decoder to the operator.
type Decoded<E> = std::result::Result<(u64, HdrImage), E>;

/// Run a video through the pipeline: frames read from `source` by `threads.decoders`
/// threads, `map` (the operator: typically [`Observer::frame`]) on the calling thread in
/// frame order into a display image, and `threads.encoders` threads encoding each mapped
/// frame and writing it into `sink` in frame order. Stops at the end of the source or at
/// the first error, after writing every frame before it; the error returned is that of
/// the earliest frame. Returns how many frames were written and where the time went.
pub fn run<E, S, K, F>(source: &S, mut map: F, sink: &K, threads: Threads) -> Result<Timings, E>
where
    E: Send,
    S: Source<E>,
    K: Sink<E>,
    F: FnMut(u64, &mut HdrImage, &mut DisplayImage) -> Result<K::Frame, E>,
{
    let start = Instant::now();
    let decoders = if source.in_order() {
        1
    } else {
        threads.decoders.max(1)
    };
    let encoders = threads.encoders.max(1);
    let clocks: [Clock; 6] = Default::default();
    let [decoding, operating, starved, blocked, encoding, writing] = &clocks;
    // Decoders: frame numbers are handed out in order; `stop` is the first frame that will
    // not be passed on (the end, an error, or 0 once the operator stops listening).
    let next_index = AtomicU64::new(0);
    let stop = AtomicU64::new(u64::MAX);
    let decode_turns = Turns::new();
    let halt = |at: u64| {
        stop.fetch_min(at, Ordering::SeqCst);
        decode_turns.wake();
    };
    // Encoders: `failed` once a frame could not be encoded or written (its error kept).
    let write_turns = Turns::new();
    let failed = AtomicBool::new(false);
    let first_error: Mutex<Option<E>> = Mutex::new(None);
    let written = AtomicU64::new(0);
    let made_hdr = AtomicU64::new(0);

    let operated = std::thread::scope(|s| {
        let (to_operator, decoded) = mpsc::sync_channel::<Decoded<E>>(0);
        let (free_hdr, reused_hdr) = mpsc::channel::<HdrImage>();
        let reused_hdr = Arc::new(Mutex::new(reused_hdr));
        let (to_encoders, mapped) = mpsc::sync_channel::<(u64, DisplayImage, K::Frame)>(0);
        let mapped = Arc::new(Mutex::new(mapped));
        let (free_display, reused_display) = mpsc::channel::<DisplayImage>();

        for _ in 0..decoders {
            let (to_operator, reused_hdr) = (to_operator.clone(), Arc::clone(&reused_hdr));
            let (next_index, stop, decode_turns, made_hdr) =
                (&next_index, &stop, &decode_turns, &made_hdr);
            spawn(s, "video-decoder", move || {
                let mut bytes = Vec::new();
                loop {
                    let index = next_index.fetch_add(1, Ordering::SeqCst);
                    if index >= stop.load(Ordering::SeqCst) {
                        return;
                    }
                    // A free image: one handed back, or a new one while fewer than one per
                    // decoder and one for the operator exist, or wait for one.
                    let reused = reused_hdr.lock().unwrap_or_else(|e| e.into_inner());
                    let image = match reused.try_recv() {
                        Ok(image) => image,
                        Err(_) if made_hdr.fetch_add(1, Ordering::SeqCst) <= decoders as u64 => {
                            HdrImage::zeros(0, 0)
                        }
                        Err(_) => match reused.recv() {
                            Ok(image) => image,
                            Err(_) => return, // the operator has stopped
                        },
                    };
                    drop(reused);
                    let mut image = image;
                    let read = decoding.time(|| source.read(index, &mut bytes, &mut image));
                    let frame = match read {
                        Ok(true) => Ok((index, image)),
                        Ok(false) => {
                            halt(index);
                            return;
                        }
                        Err(e) => Err(e),
                    };
                    let failed = frame.is_err();
                    if decode_turns
                        .wait(index, || stop.load(Ordering::SeqCst) <= index)
                        .is_none()
                    {
                        return;
                    }
                    let sent = to_operator.send(frame).is_ok();
                    decode_turns.done();
                    if !sent {
                        halt(0);
                        return;
                    }
                    if failed {
                        halt(index + 1);
                        return;
                    }
                }
            });
        }
        drop(to_operator);
        drop(reused_hdr);

        for _ in 0..encoders {
            let (mapped, free_display) = (Arc::clone(&mapped), free_display.clone());
            let (write_turns, failed, first_error, written) =
                (&write_turns, &failed, &first_error, &written);
            spawn(s, "video-encoder", move || {
                let mut bytes = Vec::new();
                loop {
                    let job = mapped.lock().unwrap_or_else(|e| e.into_inner()).recv();
                    let Ok((index, display, frame)) = job else {
                        return; // no more frames
                    };
                    if failed.load(Ordering::SeqCst) {
                        // An earlier frame failed: hand the image back (the operator may
                        // be waiting for it) and stop.
                        let _ = free_display.send(display);
                        return;
                    }
                    let encoded = encoding.time(|| sink.encode(index, &display, &mut bytes));
                    // The operator may have finished: the image is then simply dropped.
                    let _ = free_display.send(display);
                    if write_turns
                        .wait(index, || failed.load(Ordering::SeqCst))
                        .is_none()
                    {
                        return;
                    }
                    let result =
                        encoded.and_then(|()| writing.time(|| sink.write(index, &bytes, frame)));
                    let ok = result.is_ok();
                    if let Err(e) = result {
                        *first_error.lock().unwrap_or_else(|e| e.into_inner()) = Some(e);
                        failed.store(true, Ordering::SeqCst);
                    } else {
                        written.fetch_add(1, Ordering::SeqCst);
                    }
                    write_turns.done();
                    if !ok {
                        return;
                    }
                }
            });
        }
        drop(free_display);
        drop(mapped);

        // The operator, on this thread, in frame order. Its end drops the channels:
        // nothing more for the encoders (they finish the frames they have) or from the
        // decoders (they stop).
        let operated = operate(
            Stages {
                decoded,
                free_hdr,
                to_encoders,
                reused_display,
                encoders,
            },
            &mut map,
            [operating, starved, blocked],
        );
        halt(0);
        operated
    });
    // The encoders' error is for an earlier frame than the operator's (a frame reaches
    // them only after the operator is done with it).
    if let Some(e) = first_error.into_inner().unwrap_or_else(|e| e.into_inner()) {
        return Err(e);
    }
    operated?;
    let [decoding, operator, starved, blocked, encoding, writing] =
        clocks.each_ref().map(Clock::get);
    Ok(Timings {
        frames: written.into_inner(),
        threads: (decoders, encoders),
        wall: start.elapsed(),
        decoding,
        operator,
        operator_waiting_for_frames: starved,
        operator_waiting_for_encoders: blocked,
        encoding,
        writing,
    })
}

/// The operator's ends of the pipeline's channels.
struct Stages<E, T> {
    /// Decoded frames, in order.
    decoded: mpsc::Receiver<Decoded<E>>,
    /// HDR images back to the decoders.
    free_hdr: mpsc::Sender<HdrImage>,
    /// Mapped frames to the encoders.
    to_encoders: mpsc::SyncSender<(u64, DisplayImage, T)>,
    /// Display images back from the encoders.
    reused_display: mpsc::Receiver<DisplayImage>,
    /// Encoder threads (one display image each, and one for the operator).
    encoders: usize,
}

/// The operator stage of [`run`]: every decoded frame, in order, through `map` into a
/// display image (reused, or one of at most `encoders + 1`), handed to an encoder. Ends
/// at the end of the frames, at the first error (returned), or when the encoders stop
/// (their error is theirs to report). `[operating, starved, blocked]` time the map and
/// the waits.
fn operate<E, T, F>(stages: Stages<E, T>, map: &mut F, clocks: [&Clock; 3]) -> Result<(), E>
where
    F: FnMut(u64, &mut HdrImage, &mut DisplayImage) -> Result<T, E>,
{
    let [operating, starved, blocked] = clocks;
    let Stages {
        decoded,
        free_hdr,
        to_encoders,
        reused_display,
        encoders,
    } = stages;
    let mut made_display = 0;
    loop {
        let Ok(frame) = starved.time(|| decoded.recv()) else {
            return Ok(()); // every frame has been read
        };
        let (index, mut hdr) = frame?;
        let mut display = match reused_display.try_recv() {
            Ok(d) => d,
            Err(_) if made_display <= encoders => {
                made_display += 1;
                DisplayImage::default()
            }
            Err(_) => match blocked.time(|| reused_display.recv()) {
                Ok(d) => d,
                Err(_) => return Ok(()), // the encoders stopped at an error
            },
        };
        let out = operating.time(|| map(index, &mut hdr, &mut display))?;
        // Back to the decoders for a later frame (if they have finished, dropped).
        let _ = free_hdr.send(hdr);
        if blocked
            .time(|| to_encoders.send((index, display, out)))
            .is_err()
        {
            return Ok(()); // the encoders stopped at an error, which they report
        }
    }
}

/// Numbered HDR files as a [`Source`]: frame `k` is `paths[k]`, read with
/// [`io::read_scaled_into`] (any format the library reads, detected from its first
/// bytes), its values multiplied by [`FileFrames::with_scale`]'s factor.
#[derive(Debug, Clone)]
pub struct FileFrames {
    paths: Vec<PathBuf>,
    limits: Limits,
    scale: f32,
}

impl FileFrames {
    /// The frames `paths`, in order, each read within `limits`, in the files' own units.
    pub fn new(paths: Vec<PathBuf>, limits: Limits) -> Self {
        FileFrames {
            paths,
            limits,
            scale: 1.0,
        }
    }

    /// The frames with every value multiplied by `factor` as they are decoded (a unit
    /// conversion into cd/m², `visadapt video --scale`; see [`io::read_scaled_into`]).
    pub fn with_scale(self, factor: f32) -> Self {
        FileFrames {
            scale: factor,
            ..self
        }
    }

    /// The frames' paths.
    pub fn paths(&self) -> &[PathBuf] {
        &self.paths
    }
}

impl Source<Error> for FileFrames {
    fn read(&self, index: u64, bytes: &mut Vec<u8>, image: &mut HdrImage) -> Result<bool> {
        let Some(path) = usize::try_from(index).ok().and_then(|k| self.paths.get(k)) else {
            return Ok(false);
        };
        io::read_scaled_into(path, &self.limits, self.scale, bytes, image)?;
        Ok(true)
    }
}

/// Files as a [`Sink`]: frame `k` goes to `paths[k]` in `format`, written atomically
/// ([`io::display::write_atomically`]: complete or not at all). For PNG frames,
/// [`PngCompression::Fdeflate`](io::display::PngCompression::Fdeflate) spends the least CPU time per frame on textured and
/// photographic frames (see there), for files about the size of `Rle`'s: the `video`
/// command's default.
#[derive(Debug, Clone)]
pub struct FileSink {
    paths: Vec<PathBuf>,
    format: OutputFormat,
}

impl FileSink {
    /// Frame `k` to `paths[k]`, in `format`.
    pub fn new(paths: Vec<PathBuf>, format: OutputFormat) -> Self {
        FileSink { paths, format }
    }

    /// Where frame `index` goes.
    pub fn path(&self, index: u64) -> Result<&std::path::Path> {
        usize::try_from(index)
            .ok()
            .and_then(|k| self.paths.get(k))
            .map(PathBuf::as_path)
            .ok_or_else(|| Error::invalid("frame", index, "has no output file"))
    }
}

impl Sink<Error> for FileSink {
    type Frame = ();

    fn encode(&self, _index: u64, image: &DisplayImage, bytes: &mut Vec<u8>) -> Result<()> {
        self.format.encode_into(image, bytes)
    }

    fn write(&self, index: u64, bytes: &[u8], (): ()) -> Result<()> {
        write_file(self.path(index)?, bytes)
    }
}

/// Write encoded bytes to `path`, atomically (see [`io::display::write_atomically`]).
pub fn write_file(path: &std::path::Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    io::display::write_atomically(path, |w| Ok(w.write_all(bytes)?))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Frames of `w × h` at luminance `levels[k]`, with a gradient so that the blur and
    /// the mapping do real work; counts the HDR images it had to allocate.
    struct Levels {
        levels: Vec<f32>,
        fail_at: Option<u64>,
        /// HDR images the pipeline handed over empty, to be allocated here.
        fresh: AtomicU64,
    }

    impl Levels {
        fn new(levels: Vec<f32>) -> Self {
            Levels {
                levels,
                fail_at: None,
                fresh: AtomicU64::new(0),
            }
        }
    }

    /// Fill `image` with a frame at `l`; true if it had to be allocated.
    fn fill(image: &mut HdrImage, l: f32) -> bool {
        let (w, h) = (48, 24);
        let fresh = image.len() != w * h;
        if fresh {
            *image = HdrImage::zeros(w, h);
        }
        for (i, y) in image.y.iter_mut().enumerate() {
            *y = l * (0.05 + (i % w) as f32 / w as f32);
        }
        for i in 0..image.len() {
            image.x[i] = 0.9505 * image.y[i];
            image.z[i] = 1.089 * image.y[i];
        }
        image.absolute_units = true;
        fresh
    }

    impl Source<Error> for Levels {
        fn read(&self, index: u64, _: &mut Vec<u8>, image: &mut HdrImage) -> Result<bool> {
            if Some(index) == self.fail_at {
                return Err(Error::decode("test", format!("frame {index} is damaged")));
            }
            let Some(&l) = self.levels.get(index as usize) else {
                return Ok(false);
            };
            if fill(image, l) {
                self.fresh.fetch_add(1, Ordering::SeqCst);
            }
            // Spread the decoders' finishing order.
            std::thread::sleep(Duration::from_millis((index * 7) % 5));
            Ok(true)
        }
    }

    /// Encodes a frame as its green plane's bytes and keeps what it writes, in order.
    #[derive(Default)]
    struct Keep {
        written: Mutex<Vec<(u64, Vec<u8>)>>,
        fail_at: Option<u64>,
    }

    impl Sink<Error> for Keep {
        type Frame = u64;
        fn encode(&self, index: u64, image: &DisplayImage, bytes: &mut Vec<u8>) -> Result<()> {
            std::thread::sleep(Duration::from_millis((index * 3) % 4));
            if Some(index) == self.fail_at {
                return Err(Error::Unsupported(format!(
                    "frame {index} cannot be encoded"
                )));
            }
            bytes.clear();
            bytes.extend(image.g.iter().flat_map(|v| v.to_le_bytes()));
            Ok(())
        }
        fn write(&self, index: u64, bytes: &[u8], frame: u64) -> Result<()> {
            assert_eq!(index, frame);
            self.written.lock().unwrap().push((index, bytes.to_vec()));
            Ok(())
        }
    }

    fn levels() -> Vec<f32> {
        let mut l = vec![500.0; 6];
        l.extend([0.05; 8]);
        l.extend([200.0; 5]);
        l.extend([3.0; 6]);
        l
    }

    /// The frames one after another, without the pipeline: the reference.
    fn one_by_one(levels: &[f32]) -> Vec<Vec<u8>> {
        let mut eye = Observer::new(ViewingConditions::default(), 5.0).unwrap();
        let (mut hdr, mut out) = (HdrImage::zeros(0, 0), DisplayImage::default());
        levels
            .iter()
            .map(|&l| {
                fill(&mut hdr, l);
                eye.frame(&hdr, &mut out).unwrap();
                out.g.iter().flat_map(|v| v.to_le_bytes()).collect()
            })
            .collect()
    }

    /// The pipeline with an [`Observer`]; also returns how many display images it handed
    /// over empty (to be allocated by the operator).
    fn pipeline(source: &Levels, sink: &Keep, threads: Threads) -> (Result<Timings>, usize) {
        let mut eye = Observer::new(ViewingConditions::default(), 5.0).unwrap();
        let mut fresh = 0;
        let t = run(
            source,
            |k, hdr: &mut HdrImage, out: &mut DisplayImage| {
                fresh += usize::from(out.g.capacity() == 0);
                eye.frame(hdr, out)?;
                Ok(k)
            },
            sink,
            threads,
        );
        (t, fresh)
    }

    #[test]
    fn every_thread_count_writes_the_frames_of_one_after_another_in_order() {
        let want = one_by_one(&levels());
        for (decoders, encoders) in [(1, 1), (2, 2), (3, 1), (1, 3), (4, 4)] {
            let source = Levels::new(levels());
            let sink = Keep::default();
            let (t, fresh_display) = pipeline(&source, &sink, Threads { decoders, encoders });
            let t = t.unwrap();
            assert_eq!(t.frames, want.len() as u64);
            assert_eq!(t.threads, (decoders, encoders));
            let written = sink.written.into_inner().unwrap();
            let order: Vec<u64> = written.iter().map(|(k, _)| *k).collect();
            assert_eq!(order, (0..want.len() as u64).collect::<Vec<_>>());
            for (k, (_, bytes)) in written.iter().enumerate() {
                assert!(
                    *bytes == want[k],
                    "frame {k} with {decoders}/{encoders} threads"
                );
            }
            // Memory is bounded by the threads, not the frames: at most one HDR image per
            // decoder plus the operator's, one display image per encoder plus the
            // operator's were ever allocated (25 frames went through).
            let fresh_hdr = source.fresh.into_inner() as usize;
            assert!(
                fresh_hdr <= decoders + 1,
                "{fresh_hdr} HDR images, {decoders} decoders"
            );
            assert!(
                fresh_display <= encoders + 1,
                "{fresh_display} display images, {encoders} encoders"
            );
        }
    }

    #[test]
    fn a_bad_frame_stops_the_video_after_the_frames_before_it() {
        let want = one_by_one(&levels());
        for threads in [
            Threads {
                decoders: 1,
                encoders: 1,
            },
            Threads {
                decoders: 3,
                encoders: 3,
            },
        ] {
            // A frame that cannot be decoded.
            let mut source = Levels::new(levels());
            source.fail_at = Some(9);
            let sink = Keep::default();
            let e = pipeline(&source, &sink, threads).0.unwrap_err();
            assert!(e.to_string().contains("frame 9 is damaged"), "{e}");
            let written = sink.written.into_inner().unwrap();
            assert_eq!(written.len(), 9);
            assert!(written.iter().all(|(k, b)| *b == want[*k as usize]));
            // A frame that cannot be encoded (the later frames may already be encoded).
            let source = Levels::new(levels());
            let sink = Keep {
                fail_at: Some(4),
                ..Keep::default()
            };
            let e = pipeline(&source, &sink, threads).0.unwrap_err();
            assert!(e.to_string().contains("frame 4 cannot be encoded"), "{e}");
            assert_eq!(sink.written.into_inner().unwrap().len(), 4);
            // A frame of another size: the operator's error, after the frames before it.
            let source = Levels::new(levels());
            let sink = Keep::default();
            let mut eye = Observer::new(ViewingConditions::default(), 5.0).unwrap();
            let e = run(
                &source,
                |k, hdr: &mut HdrImage, out: &mut DisplayImage| {
                    if k == 12 {
                        *hdr = HdrImage::zeros(8, 8);
                        hdr.y.fill(1.0);
                    }
                    eye.frame(hdr, out)?;
                    Ok(k)
                },
                &sink,
                threads,
            )
            .unwrap_err();
            assert!(
                e.to_string().contains("8x8") && e.to_string().contains("48x24"),
                "{e}"
            );
            assert_eq!(sink.written.into_inner().unwrap().len(), 12);
        }
    }

    /// An observer of local adaptation shows the map it keeps by its planes' sizes, not
    /// their samples (the images' and the map's own `Debug`).
    #[test]
    fn an_observers_debug_shows_its_maps_size_not_its_samples() {
        let conditions = ViewingConditions {
            adaptation: operator::AdaptationMode::Local(crate::local::LocalAdaptation::default()),
            ..ViewingConditions::default()
        };
        let mut eye = Observer::new(conditions, 4.0).unwrap();
        let (mut hdr, mut out) = (HdrImage::zeros(0, 0), DisplayImage::default());
        fill(&mut hdr, 1000.0);
        eye.frame(&hdr, &mut out).unwrap();
        let shown = format!("{eye:?}");
        assert!(shown.contains("offset_log: <1152 samples>"), "{shown}");
        assert!(shown.len() < 4000, "{} characters", shown.len());
    }

    #[test]
    fn the_observer_adapts_to_the_first_frame_then_steps_by_one_over_fps() {
        let mut eye = Observer::new(ViewingConditions::default(), 4.0).unwrap();
        let (mut hdr, mut out) = (HdrImage::zeros(0, 0), DisplayImage::default());
        fill(&mut hdr, 1000.0);
        let first = eye.frame(&hdr, &mut out).unwrap();
        assert_eq!(first.t_seconds, 0.0);
        assert!(first.state.is_adapted());
        fill(&mut hdr, 0.01);
        let second = eye.frame(&hdr, &mut out).unwrap();
        assert_eq!(second.t_seconds, 0.25);
        // The same state as stepping the library's state by hand.
        let mut by_hand = first.state.clone();
        by_hand.step_to(0.25, &second.report).unwrap();
        assert_eq!(second.state, by_hand);
        assert!(second.state.cone_excess_log() > 1.0);
        assert_eq!(eye.frames_seen(), 2);
        for fps in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(Observer::new(ViewingConditions::default(), fps).is_err());
        }
    }
}
