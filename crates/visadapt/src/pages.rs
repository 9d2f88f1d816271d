//! A global allocator that puts the large buffers of an image (planes, encoded files) on
//! transparent huge pages, for programs built on the library (the `visadapt` command
//! installs it; a program of its own opts in with `#[global_allocator]`).
//!
//! Why: every fresh page of memory a process touches costs a page fault, in which the
//! kernel clears the page. One 1920×1080 `map` touches about 36 MiB of fresh memory
//! (the decoded planes, the mapped planes, the encoded file): 9.3 thousand faults of
//! 4 KiB pages, which took 47 of its 95 ms of CPU time on the 2-core virtual machine the
//! README's figures come from (`perf stat -e page-faults,task-clock`). A 2 MiB huge page
//! is one fault where 4 KiB pages take 512; clearing the memory costs the same, the
//! faults' overhead goes.
//!
//! How: an allocation of at least [`HUGE_PAGE`] bytes is its own anonymous mapping,
//! aligned to 2 MiB and marked `MADV_HUGEPAGE` (the kernel's setting
//! `/sys/kernel/mm/transparent_hugepage/enabled` is `madvise` on most distributions,
//! which gives huge pages only to memory so marked). The
//! kernel hands out such memory already zeroed, so zeroed allocations (`vec![0.0; n]`)
//! are not cleared a second time. Smaller allocations, and every allocation off Linux,
//! go to the system allocator unchanged. A freed mapping is kept for the next allocation
//! of its length (up to sixteen of them, and never more memory, live and kept, than was
//! live at the peak: see `spares`), so that buffers allocated over and over do not fault
//! in fresh pages each time. A mapping that fails is reported as an
//! allocation failure, as the system allocator's would be; advice the kernel refuses
//! (huge pages switched off) only loses the speed.
//!
//! Memory use: a mapping is a whole number of huge pages, each resident whole (2 MiB)
//! once touched, so a buffer takes less than 2 MiB more than its size.
//!
//! This module and `simd` (the runtime CPU dispatch) hold the crate's only `unsafe` code.
#![allow(unsafe_code)]

use std::alloc::{GlobalAlloc, Layout, System};

/// The size of a transparent huge page on x86-64 and on most aarch64 kernels (2 MiB, the
/// size of the memory one second-level page-table entry maps), and the smallest
/// allocation placed on its own mapping.
pub const HUGE_PAGE: usize = 2 << 20;

/// The global allocator described in the [module documentation](self): allocations of
/// at least [`HUGE_PAGE`] bytes on transparent huge pages (Linux), all others, and all
/// allocations elsewhere, from [`System`].
///
/// ```
/// #[global_allocator]
/// static ALLOCATOR: visadapt::pages::HugePages = visadapt::pages::HugePages;
///
/// let plane = vec![0.0f32; 1920 * 1080];
/// assert!(plane.iter().all(|&v| v == 0.0));
/// ```
#[derive(Debug, Default, Clone, Copy)]
pub struct HugePages;

/// Whether an allocation of `layout` gets its own huge-page mapping. Decided from the
/// layout alone, so that `dealloc` takes the path `alloc` took.
#[inline]
fn own_mapping(layout: &Layout) -> bool {
    cfg!(target_os = "linux") && layout.size() >= HUGE_PAGE && layout.align() <= HUGE_PAGE
}

// SAFETY (the whole impl): allocations routed to `System` are `System`'s, with the caller's
// layouts unchanged. Allocations with their own mapping are `len` bytes of a private
// anonymous mapping starting at a 2 MiB boundary; `len >= layout.size()` and the start is
// aligned to 2 MiB, hence to `layout.align()` (checked by `own_mapping`). `dealloc` gets
// the same layout as `alloc` (the `GlobalAlloc` contract), recomputes the same `len` and
// keeps or unmaps exactly that range; a kept mapping is handed out again only as a whole
// for the same `len`, or cut to a shorter `len` (its tail unmapped), and never to two
// owners (`spares` takes it out under its lock). Nothing here allocates.
unsafe impl GlobalAlloc for HugePages {
    #[inline]
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if own_mapping(&layout) {
            own(layout.size()).0
        } else {
            // SAFETY: the caller's contract, passed on.
            unsafe { System.alloc(layout) }
        }
    }

    #[inline]
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if own_mapping(&layout) {
            match own(layout.size()) {
                // SAFETY: a reused mapping of at least `layout.size()` bytes, now ours.
                (p, false) => unsafe {
                    p.write_bytes(0, layout.size());
                    p
                },
                // Fresh anonymous memory reads as zero (or null: the mapping failed).
                (p, true) => p,
            }
        } else {
            // SAFETY: the caller's contract, passed on.
            unsafe { System.alloc_zeroed(layout) }
        }
    }

    #[inline]
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        if own_mapping(&layout) {
            let len = mapping_len(layout.size());
            if !spares::keep(ptr, len) {
                unmap(ptr, len);
                spares::gone(len);
            }
        } else {
            // SAFETY: `ptr` came from `System` with this layout (same routing as alloc).
            unsafe { System.dealloc(ptr, layout) }
        }
    }

    #[inline]
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: the caller guarantees `new_size` with `layout.align()` is a valid layout.
        let new_layout = unsafe { Layout::from_size_align_unchecked(new_size, layout.align()) };
        if !own_mapping(&layout) && !own_mapping(&new_layout) {
            // SAFETY: both on `System`: its realloc, with the caller's contract.
            return unsafe { System.realloc(ptr, layout, new_size) };
        }
        // Crossing to, from or between own mappings: new block, copy, free the old one.
        // SAFETY: `new_size` is non-zero (the caller's contract), as `alloc` requires.
        let new = unsafe { self.alloc(new_layout) };
        if !new.is_null() {
            // SAFETY: both blocks are valid for the smaller size and do not overlap.
            unsafe {
                std::ptr::copy_nonoverlapping(ptr, new, layout.size().min(new_size));
                self.dealloc(ptr, layout);
            }
        }
        new
    }
}

/// Freed mappings kept for the next allocation of the same length, so that a program
/// that allocates and frees image-sized buffers over and over (a batch of frames, the
/// viewer's renders, the passes of one `map`) reuses memory whose pages are already
/// there instead of faulting in fresh ones, as the system allocator does by keeping
/// freed blocks of up to 32 MiB in its heap.
///
/// Bounded: the mappings live and kept together never exceed the most that were live
/// at one moment before (the *peak*), so keeping costs no memory the process did not
/// already hold. An allocation that finds no kept mapping of its length is mapped fresh
/// while that bound leaves room; otherwise it takes the head of the smallest larger kept
/// mapping (its tail unmapped), or unmaps kept mappings, smallest first, until the new
/// one fits under the bound. An allocation of a length none of the kept ones has (a
/// preview's plane between full frames, an encoded file's buffer as it grows) therefore
/// no longer unmaps every kept mapping, as it did before, so that the next full-size
/// planes do not fault in fresh memory.
mod spares {
    use std::sync::Mutex;

    /// How many freed mappings are kept at most. Our choice: more than the buffers of
    /// the frames `video` keeps in flight (decoded planes, display planes, encoded
    /// files); the memory they hold is bounded by the peak rule, not by this count.
    pub(super) const SLOTS: usize = 16;

    /// A kept mapping: its start and its length (0: an empty slot).
    #[derive(Clone, Copy)]
    struct Spare(*mut u8, usize);

    const EMPTY: Spare = Spare(std::ptr::null_mut(), 0);

    // SAFETY: a kept mapping belongs to no one until `take` hands it out; the pointer is
    // only moved between threads under the mutex, never dereferenced there.
    unsafe impl Send for Spare {}

    /// The kept mappings and the bytes of own mappings live now and at the peak.
    struct Kept {
        slots: [Spare; SLOTS],
        live: usize,
        peak: usize,
    }

    impl Kept {
        fn kept(&self) -> usize {
            self.slots.iter().map(|s| s.1).sum()
        }

        fn remove(&mut self, i: usize) -> Spare {
            std::mem::replace(&mut self.slots[i], EMPTY)
        }
    }

    static KEPT: Mutex<Kept> = Mutex::new(Kept {
        slots: [EMPTY; SLOTS],
        live: 0,
        peak: 0,
    });

    fn lock() -> std::sync::MutexGuard<'static, Kept> {
        // Nothing here panics while the lock is held; a poisoned lock is still usable.
        KEPT.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Account for a new mapping of `len` bytes: a kept one to reuse (of that length, or
    /// the head of a longer one whose tail is unmapped here), or `None` for a fresh one,
    /// after unmapping here the kept ones it displaces (see the module documentation).
    /// [`gone`] takes it back if a fresh mapping fails.
    pub(super) fn take(len: usize) -> Option<*mut u8> {
        let mut k = lock();
        k.live += len;
        k.peak = k.peak.max(k.live);
        if let Some(i) = k.slots.iter().position(|s| s.1 == len) {
            return Some(k.remove(i).0);
        }
        if k.live + k.kept() <= k.peak {
            return None;
        }
        let longer = (0..SLOTS)
            .filter(|&i| k.slots[i].1 > len)
            .min_by_key(|&i| k.slots[i].1);
        if let Some(i) = longer {
            let Spare(p, l) = k.remove(i);
            drop(k);
            super::unmap(p.wrapping_add(len), l - len);
            return Some(p);
        }
        let mut dropped = [EMPTY; SLOTS];
        while k.live + k.kept() > k.peak {
            let Some(i) = (0..SLOTS)
                .filter(|&i| k.slots[i].1 > 0)
                .min_by_key(|&i| k.slots[i].1)
            else {
                break;
            };
            dropped[i] = k.remove(i);
        }
        drop(k);
        unmap_all(&dropped);
        None
    }

    /// A mapping of `len` bytes is gone (unmapped, or never made).
    pub(super) fn gone(len: usize) {
        lock().live -= len;
    }

    /// Keep the mapping at `ptr` of `len` bytes, freed; `false` when every slot is full
    /// (the caller unmaps it, then calls [`gone`]).
    pub(super) fn keep(ptr: *mut u8, len: usize) -> bool {
        let mut k = lock();
        match k.slots.iter().position(|s| s.1 == 0) {
            Some(i) => {
                k.slots[i] = Spare(ptr, len);
                k.live -= len;
                true
            }
            None => false,
        }
    }

    /// Unmap the mappings in `dropped`, taken out of the kept ones.
    fn unmap_all(dropped: &[Spare; SLOTS]) {
        for spare in dropped.iter().filter(|s| s.1 > 0) {
            super::unmap(spare.0, spare.1);
        }
    }

    /// Unmap every kept mapping (tests start from none kept).
    #[cfg(test)]
    pub(super) fn clear() {
        let mut dropped = [EMPTY; SLOTS];
        std::mem::swap(&mut lock().slots, &mut dropped);
        unmap_all(&dropped);
    }

    /// How many mappings are kept now, their bytes, and the bytes live and at the peak.
    #[cfg(test)]
    pub(super) fn state() -> (usize, usize, usize, usize) {
        let k = lock();
        let count = k.slots.iter().filter(|s| s.1 > 0).count();
        (count, k.kept(), k.live, k.peak)
    }
}

/// The length of the mapping that holds `size` bytes: whole huge pages, so that the tail
/// of a buffer is on a huge page too (a 1920×1080 plane of `f32` is 3.96 huge pages; on
/// small pages its last 1.9 MiB alone took 490 faults). `size` is a layout's, at most
/// `isize::MAX`, so this does not overflow.
fn mapping_len(size: usize) -> usize {
    size.next_multiple_of(HUGE_PAGE)
}

/// An own mapping for `size` bytes, kept or fresh (see `spares`), and whether it is
/// fresh (reads as zero); null when the kernel refuses the memory.
fn own(size: usize) -> (*mut u8, bool) {
    let len = mapping_len(size);
    match spares::take(len) {
        Some(p) => (p, false),
        None => {
            let p = map_huge(len);
            if p.is_null() {
                spares::gone(len);
            }
            (p, true)
        }
    }
}

/// A private anonymous mapping of `len` bytes, a multiple of [`HUGE_PAGE`], starting at
/// a 2 MiB boundary, marked for huge pages; null when the kernel refuses the memory.
#[cfg(target_os = "linux")]
fn map_huge(len: usize) -> *mut u8 {
    use rustix::mm::{Advice, MapFlags, ProtFlags, madvise, mmap_anonymous, munmap};
    let Some(reserve) = len.checked_add(HUGE_PAGE) else {
        return std::ptr::null_mut();
    };
    // SAFETY: a new mapping at an address of the kernel's choosing touches no existing
    // memory.
    let Ok(base) = (unsafe {
        mmap_anonymous(
            std::ptr::null_mut(),
            reserve,
            ProtFlags::READ | ProtFlags::WRITE,
            MapFlags::PRIVATE,
        )
    }) else {
        return std::ptr::null_mut();
    };
    let base = base.cast::<u8>();
    let head = (base as usize).next_multiple_of(HUGE_PAGE) - base as usize;
    let start = base.wrapping_add(head);
    let tail = reserve - head - len;
    // SAFETY: the head and the tail are the parts of the new mapping outside
    // [start, start + len), page-aligned (base, len and HUGE_PAGE are), owned by no one.
    unsafe {
        if head > 0 {
            let _ = munmap(base.cast(), head);
        }
        if tail > 0 {
            let _ = munmap(start.wrapping_add(len).cast(), tail);
        }
        // Advice only: without huge pages the memory is still valid.
        let _ = madvise(start.cast(), len, Advice::LinuxHugepage);
    }
    start
}

/// Unmap `len` bytes at `ptr`: a whole mapping made by [`map_huge`], or its tail from a
/// huge-page boundary.
#[cfg(target_os = "linux")]
fn unmap(ptr: *mut u8, len: usize) {
    // SAFETY: `ptr` and `len` lie within a mapping made by `map_huge` that no one uses
    // any more (freed by `dealloc`'s contract, or a kept one taken out of `spares`).
    unsafe {
        let _ = rustix::mm::munmap(ptr.cast(), len);
    }
}

#[cfg(not(target_os = "linux"))]
fn map_huge(_: usize) -> *mut u8 {
    unreachable!("own mappings are made on Linux only")
}

#[cfg(not(target_os = "linux"))]
fn unmap(_: *mut u8, _: usize) {
    unreachable!("own mappings are made on Linux only")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fill(ptr: *mut u8, len: usize) {
        // SAFETY: callers pass a live block of at least `len` bytes.
        let s = unsafe { std::slice::from_raw_parts_mut(ptr, len) };
        for (i, b) in s.iter_mut().enumerate() {
            *b = (i % 251) as u8;
        }
    }

    fn holds_pattern(ptr: *const u8, len: usize) -> bool {
        // SAFETY: callers pass a live block of at least `len` bytes.
        let s = unsafe { std::slice::from_raw_parts(ptr, len) };
        s.iter().enumerate().all(|(i, &b)| b == (i % 251) as u8)
    }

    /// Blocks on both sides of the threshold are aligned as asked, zeroed when asked, and
    /// keep their contents when reallocated across the threshold in both directions.
    /// The tests share the kept mappings; they run one at a time.
    static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

    #[test]
    fn blocks_keep_their_contents_across_the_threshold() {
        let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
        let a = HugePages;
        let cases = [
            (64, 8),
            (HUGE_PAGE - 1, 64),
            (HUGE_PAGE, 4096),
            (3 * HUGE_PAGE + 5, 16),
        ];
        for (size, align) in cases {
            let layout = Layout::from_size_align(size, align).unwrap();
            for new_size in [size / 2 + 1, 2 * size + HUGE_PAGE] {
                // SAFETY: non-zero sizes; every block is freed with the layout it has.
                unsafe {
                    let p = a.alloc_zeroed(layout);
                    assert!(!p.is_null());
                    assert_eq!(p as usize % align, 0, "{size}");
                    assert!(std::slice::from_raw_parts(p, size).iter().all(|&b| b == 0));
                    fill(p, size);
                    let q = a.realloc(p, layout, new_size);
                    assert!(!q.is_null());
                    assert!(holds_pattern(q, size.min(new_size)), "{size} -> {new_size}");
                    let new_layout = Layout::from_size_align(new_size, align).unwrap();
                    fill(q, new_size);
                    let r = a.realloc(q, new_layout, size);
                    assert!(!r.is_null());
                    assert!(holds_pattern(r, size.min(new_size)), "{new_size} -> {size}");
                    a.dealloc(r, layout);
                }
            }
        }
    }

    /// A large block is its own mapping, starting on a 2 MiB boundary and marked for huge
    /// pages (`hg` in the mapping's `VmFlags` in `/proc/self/smaps`, whatever the
    /// system's huge-page setting); freed, it is kept and handed out again for the same
    /// length (whole huge pages), zeroed when asked.
    #[cfg(target_os = "linux")]
    #[test]
    fn a_large_block_is_an_aligned_mapping_advised_for_huge_pages_and_reused() {
        let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
        let flags_of = |addr: usize| -> Option<String> {
            let smaps = std::fs::read_to_string("/proc/self/smaps").unwrap();
            let mut inside = false;
            for line in smaps.lines() {
                if let Some((range, _)) = line.split_once(' ')
                    && let Some((lo, hi)) = range.split_once('-')
                    && let (Ok(lo), Ok(hi)) =
                        (usize::from_str_radix(lo, 16), usize::from_str_radix(hi, 16))
                {
                    inside = (lo..hi).contains(&addr);
                } else if inside && let Some(flags) = line.strip_prefix("VmFlags:") {
                    return Some(flags.to_string());
                }
            }
            None
        };
        let a = HugePages;
        let layout = Layout::from_size_align(5 * HUGE_PAGE + 123, 4).unwrap();
        let same_length = Layout::from_size_align(6 * HUGE_PAGE, 4).unwrap();
        // SAFETY: non-zero sizes, each block freed with its layout.
        unsafe {
            let p = a.alloc(layout);
            assert!(!p.is_null());
            assert_eq!(p as usize % HUGE_PAGE, 0);
            let flags = flags_of(p as usize).expect("the block is mapped");
            assert!(flags.split_whitespace().any(|f| f == "hg"), "{flags}");
            p.write_bytes(7, layout.size());
            a.dealloc(p, layout);
            assert!(spares::state().0 >= 1);
            let q = a.alloc_zeroed(same_length);
            assert_eq!(q, p, "the freed mapping is reused");
            assert!(
                std::slice::from_raw_parts(q, same_length.size())
                    .iter()
                    .all(|&b| b == 0)
            );
            a.dealloc(q, same_length);
        }
    }

    /// An allocation of a length none of the kept mappings has takes the head of the
    /// shortest longer one and leaves the others kept (it used to unmap them all, so that
    /// in `video` each PNG's output buffer sent the next frame's planes to fresh pages).
    #[cfg(target_os = "linux")]
    #[test]
    fn a_miss_takes_the_shortest_longer_mapping_and_keeps_the_rest() {
        let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
        let a = HugePages;
        let plane = Layout::from_size_align(4 * HUGE_PAGE - 4096, 64).unwrap();
        let wide = Layout::from_size_align(9 * HUGE_PAGE, 64).unwrap();
        let file = Layout::from_size_align(HUGE_PAGE + 17, 1).unwrap();
        spares::clear();
        // SAFETY: non-zero sizes, each block freed with its layout.
        unsafe {
            let (p, q, w) = (a.alloc(plane), a.alloc(plane), a.alloc(wide));
            assert!(!p.is_null() && !q.is_null() && !w.is_null());
            fill(p, plane.size());
            a.dealloc(p, plane);
            a.dealloc(q, plane);
            a.dealloc(w, wide);
            assert_eq!(spares::state().0, 3);
            let f = a.alloc_zeroed(file);
            assert!([p, q].contains(&f), "the head of a kept plane's mapping");
            assert!(
                std::slice::from_raw_parts(f, file.size())
                    .iter()
                    .all(|&b| b == 0)
            );
            assert_eq!(spares::state().0, 2, "the others stay kept");
            let other = if f == p { q } else { p };
            let r = a.alloc(plane);
            assert_eq!(r, other, "the other plane's mapping is reused");
            let v = a.alloc(wide);
            assert_eq!(v, w, "so is the wide one");
            fill(f, file.size());
            assert!(holds_pattern(f, file.size()));
            a.dealloc(f, file);
            a.dealloc(r, plane);
            a.dealloc(v, wide);
        }
    }

    /// Whatever the order of allocations and frees, the mappings live and kept together
    /// never exceed the peak of those live, and every block keeps what is written to it.
    #[cfg(target_os = "linux")]
    #[test]
    fn live_and_kept_mappings_stay_under_the_peak() {
        let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
        let a = HugePages;
        let mut rng = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = |n: u64| {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            (rng % n) as usize
        };
        let mut held: Vec<(*mut u8, Layout)> = Vec::new();
        let mut peak_seen = 0;
        spares::clear();
        for _ in 0..400 {
            if held.len() < 12 && (held.is_empty() || next(3) > 0) {
                let size = HUGE_PAGE + next(6) * HUGE_PAGE + next(3) * 4096;
                let layout = Layout::from_size_align(size, 8).unwrap();
                // SAFETY: a non-zero size; freed below with this layout.
                let p = unsafe { a.alloc(layout) };
                assert!(!p.is_null());
                fill(p, size.min(3 * 4096));
                held.push((p, layout));
            } else {
                let (p, layout) = held.swap_remove(next(held.len() as u64));
                assert!(holds_pattern(p, layout.size().min(3 * 4096)));
                // SAFETY: allocated above with `layout`, freed once.
                unsafe { a.dealloc(p, layout) };
            }
            let live: usize = held.iter().map(|(_, l)| mapping_len(l.size())).sum();
            peak_seen = peak_seen.max(live);
            let (_, kept, live_counted, peak) = spares::state();
            assert_eq!(live_counted, live);
            assert!(
                live_counted + kept <= peak,
                "{live_counted} + {kept} > {peak}"
            );
        }
        for (p, layout) in held {
            // SAFETY: allocated above with `layout`, freed once.
            unsafe { a.dealloc(p, layout) };
        }
        assert!(peak_seen > 0);
    }
}
