//! Per-thread cache of swscale contexts.
//!
//! `ffmpeg_next::software::scaling::Context` is not `Send`, but readers must be (they are
//! handed to worker threads), and building a context per frame is too slow. So contexts
//! live in a small thread-local cache keyed by their geometry: a reader moved to another
//! thread simply builds a fresh one there. No `unsafe` needed.

use std::cell::RefCell;

use ffmpeg::format::Pixel;
use ffmpeg::frame;
use ffmpeg::software::scaling::{Context, Flags};
use ffmpeg_next as ffmpeg;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Key {
    pub src_format: Pixel,
    pub src_w: u32,
    pub src_h: u32,
    pub dst_format: Pixel,
    pub dst_w: u32,
    pub dst_h: u32,
}

/// Enough for a few readers/writers interleaved on one thread; each context is small.
const CAPACITY: usize = 8;

thread_local! {
    static CACHE: RefCell<Vec<(Key, Context)>> = const { RefCell::new(Vec::new()) };
}

/// Runs one conversion/scale of `input` into `output` with a cached context for `key`.
///
/// `output` must be empty or already allocated at the key's destination size and format.
pub(crate) fn scale(key: Key, input: &frame::Video, output: &mut frame::Video) -> Result<(), ffmpeg::Error> {
    CACHE.with_borrow_mut(|cache| {
        let pos = match cache.iter().position(|(k, _)| *k == key) {
            Some(pos) => pos,
            None => {
                // Same-size conversions take swscale's unscaled fast paths regardless of flags;
                // bilinear is the usual speed/quality trade-off for real resizes.
                let ctx = Context::get(
                    key.src_format,
                    key.src_w,
                    key.src_h,
                    key.dst_format,
                    key.dst_w,
                    key.dst_h,
                    Flags::BILINEAR,
                )?;
                if cache.len() >= CAPACITY {
                    cache.remove(0);
                }
                cache.push((key, ctx));
                cache.len() - 1
            }
        };
        cache[pos].1.run(input, output)
    })
}
