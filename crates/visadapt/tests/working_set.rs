//! The memory the operator and the writers allocate beyond their input (issue 9, item 5):
//! measured with a counting global allocator, in bytes per pixel.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};
use visadapt::HdrImage;
use visadapt::operator::{ViewingConditions, map, map_owned};

/// The system allocator, counting the bytes live now and the most live since a reset.
struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: forwarded unchanged to the system allocator.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            let live = LIVE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
            PEAK.fetch_max(live, Ordering::Relaxed);
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.dealloc(ptr, layout) };
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// The most bytes `f` had allocated at once beyond what was live when it started.
fn peak_extra<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let base = LIVE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let out = f();
    (out, PEAK.load(Ordering::Relaxed).saturating_sub(base))
}

/// A night scene with structure (so the blur and clipping do work), `w × h`.
fn scene(w: usize, h: usize) -> HdrImage {
    let mut im = HdrImage::zeros(w, h);
    for i in 0..w * h {
        let l = 0.05 * (1.0 + ((i * 7919) % 97) as f32 / 10.0);
        im.x[i] = 0.9505 * l;
        im.y[i] = l;
        im.z[i] = 1.089 * l;
    }
    im
}

/// A writer that keeps nothing (so that only the encoder's own memory is counted).
#[derive(Default)]
struct Discard {
    pos: u64,
    len: u64,
}

impl std::io::Write for Discard {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.pos += buf.len() as u64;
        self.len = self.len.max(self.pos);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl std::io::Seek for Discard {
    fn seek(&mut self, to: std::io::SeekFrom) -> std::io::Result<u64> {
        self.pos = match to {
            std::io::SeekFrom::Start(p) => p,
            std::io::SeekFrom::End(d) => self.len.saturating_add_signed(d),
            std::io::SeekFrom::Current(d) => self.pos.saturating_add_signed(d),
        };
        Ok(self.pos)
    }
}

#[test]
fn map_owned_and_the_exr_writer_allocate_no_second_image() {
    // One test, so that no other allocates meanwhile in this process.
    let (w, h) = (1000, 700);
    let n = (w * h) as f64;
    let conditions = ViewingConditions::default();
    let input = scene(w, h);

    // map keeps the input and makes a display image: 12 more bytes per pixel.
    let (by_ref, extra) = peak_extra(|| map(&input, &conditions).unwrap());
    let map_bpp = extra as f64 / n;
    assert!(
        map_bpp >= 12.0,
        "map: {map_bpp:.2} bytes per pixel beyond the input"
    );

    // map_owned writes the display over the input's planes: no second image (that would be
    // 12 B/pixel; what remains, 1-2 B/pixel, is the blur's per-thread scratch).
    let copy = input.clone();
    let (owned, extra) = peak_extra(move || map_owned(copy, &conditions).unwrap());
    let owned_bpp = extra as f64 / n;
    assert!(
        owned_bpp < 4.0,
        "map_owned: {owned_bpp:.2} bytes per pixel beyond the input"
    );
    // And the same picture, bit for bit.
    for (a, b) in [
        (&by_ref.image.r, &owned.image.r),
        (&by_ref.image.g, &owned.image.g),
        (&by_ref.image.b, &owned.image.b),
    ] {
        assert!(a.iter().zip(b).all(|(a, b)| a.to_bits() == b.to_bits()));
    }
    assert_eq!(by_ref.stats, owned.stats);

    // The EXR writer reads the planes where they are (it copied all three: 12 B/pixel).
    let (written, extra) = peak_extra(|| {
        let mut sink = Discard::default();
        visadapt::io::exr::write_display(&owned.image, &mut sink).map(|_| sink.len)
    });
    assert!(written.unwrap() > 0);
    let exr_bpp = extra as f64 / n;
    assert!(exr_bpp < 4.0, "EXR writer: {exr_bpp:.2} bytes per pixel");
    eprintln!(
        "beyond the input: map {map_bpp:.2}, map_owned {owned_bpp:.2}, EXR write {exr_bpp:.2} B/pixel"
    );
}
