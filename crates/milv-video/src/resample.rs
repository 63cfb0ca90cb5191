//! Frame-rate resampling as an iterator adapter shared by every reader.

use crate::{Error, Frame};

/// Resamples a stream of frames to a fixed rate by dropping or repeating frames.
///
/// Output frame `k` has `pts_ns = round(k · 1e9 / fps)` and shows the latest source frame
/// whose `pts_ns` is at or before that time (keeping its `source_index`). Output stops at the
/// last source frame's time, so there are `floor(last_pts · fps / 1e9) + 1` outputs.
/// Holds at most two source frames.
pub struct Resample<I> {
    inner: I,
    fps: f64,
    /// Next output index.
    k: u64,
    /// Latest source frame at or before the current output time.
    current: Option<Frame>,
    /// First source frame after the current output time (look-ahead).
    pending: Option<Frame>,
    exhausted: bool,
    /// A source error seen while looking ahead; reported after the frames before it.
    error: Option<Error>,
    done: bool,
}

impl<I: Iterator<Item = Result<Frame, Error>>> Resample<I> {
    /// Wraps `inner`; `fps` must be finite and positive.
    pub fn new(inner: I, fps: f64) -> Result<Self, Error> {
        crate::types::check_fps(fps)?;
        Ok(Resample {
            inner,
            fps,
            k: 0,
            current: None,
            pending: None,
            exhausted: false,
            error: None,
            done: false,
        })
    }

    /// The wrapped iterator.
    pub fn inner(&self) -> &I {
        &self.inner
    }

    /// Fills `pending` with the next source frame unless the source is exhausted.
    /// A source error ends the source; it is reported once the frames before it are out.
    fn pull(&mut self) {
        if self.pending.is_none() && !self.exhausted {
            match self.inner.next() {
                Some(Ok(f)) => self.pending = Some(f),
                Some(Err(e)) => {
                    self.error = Some(e);
                    self.exhausted = true;
                }
                None => self.exhausted = true,
            }
        }
    }

    fn step(&mut self) -> Option<Frame> {
        loop {
            let t = time_of(self.k, self.fps);
            let t_next = time_of(self.k + 1, self.fps);
            // Advance `current` to the latest source frame with pts <= t.
            loop {
                self.pull();
                match &self.pending {
                    Some(p) if p.pts_ns <= t => self.current = self.pending.take(),
                    _ => break,
                }
            }
            let Some(cur) = &self.current else {
                match &self.pending {
                    // Source starts after t: jump to the first slot at or after its first
                    // frame (one at a time could spin for ages on a huge start time).
                    Some(p) => {
                        let first = (p.pts_ns as f64 * self.fps / 1e9).ceil();
                        self.k = (self.k + 1).max(first as u64);
                        continue;
                    }
                    None => return None,
                }
            };
            if self.exhausted && self.pending.is_none() && t > cur.pts_ns {
                return None;
            }
            self.k += 1;
            // Move the frame out when no later output can show it again, else clone it.
            let reused = match &self.pending {
                Some(p) => p.pts_ns > t_next,
                None => t_next <= cur.pts_ns,
            };
            let mut frame = if reused { cur.clone() } else { self.current.take()? };
            frame.pts_ns = t;
            return Some(frame);
        }
    }
}

/// A reader's frames, resampled or not (so readers have one concrete type either way).
pub(crate) enum MaybeResample<I> {
    Plain(I),
    Resampled(Resample<I>),
}

impl<I: Iterator<Item = Result<Frame, Error>>> MaybeResample<I> {
    pub(crate) fn new(inner: I, fps: Option<f64>) -> Result<Self, Error> {
        Ok(match fps {
            Some(fps) => MaybeResample::Resampled(Resample::new(inner, fps)?),
            None => MaybeResample::Plain(inner),
        })
    }

    pub(crate) fn inner(&self) -> &I {
        match self {
            MaybeResample::Plain(i) => i,
            MaybeResample::Resampled(r) => r.inner(),
        }
    }
}

impl<I: Iterator<Item = Result<Frame, Error>>> Iterator for MaybeResample<I> {
    type Item = Result<Frame, Error>;

    fn next(&mut self) -> Option<Self::Item> {
        match self {
            MaybeResample::Plain(i) => i.next(),
            MaybeResample::Resampled(r) => r.next(),
        }
    }
}

/// Output time of slot `k` in ns; f64 is exact enough here (error < 1 ns below ~100 days).
fn time_of(k: u64, fps: f64) -> i64 {
    (k as f64 * 1e9 / fps).round() as i64
}

impl<I: Iterator<Item = Result<Frame, Error>>> Iterator for Resample<I> {
    type Item = Result<Frame, Error>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        match self.step() {
            Some(f) => Some(Ok(f)),
            None => {
                // Errors from the source end the stream, as in the readers.
                self.done = true;
                self.error.take().map(Err)
            }
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn source(n: u64, fps: f64) -> impl Iterator<Item = Result<Frame, Error>> {
        (0..n).map(move |i| {
            Ok(Frame {
                width: 1,
                height: 1,
                data: vec![i as u8; 3],
                pts_ns: (i as f64 * 1e9 / fps).round() as i64,
                source_index: i,
            })
        })
    }

    fn run(n: u64, src_fps: f64, fps: f64) -> Vec<Frame> {
        Resample::new(source(n, src_fps), fps)
            .unwrap()
            .collect::<Result<Vec<_>, _>>()
            .unwrap()
    }

    #[test]
    fn downsample_10_to_5() {
        let out = run(20, 10.0, 5.0);
        // last pts 1.9 s -> floor(1.9 * 5) + 1 = 10
        assert_eq!(out.len(), 10);
        for (k, f) in out.iter().enumerate() {
            assert_eq!(f.pts_ns, k as i64 * 200_000_000);
            assert_eq!(f.source_index, 2 * k as u64);
            assert_eq!(f.data[0], 2 * k as u8);
        }
    }

    #[test]
    fn upsample_10_to_20() {
        let out = run(20, 10.0, 20.0);
        // floor(1.9 * 20) + 1 = 39
        assert_eq!(out.len(), 39);
        for (k, f) in out.iter().enumerate() {
            assert_eq!(f.pts_ns, k as i64 * 50_000_000);
            assert_eq!(f.source_index, k as u64 / 2);
        }
    }

    #[test]
    fn non_integer_ratio() {
        let out = run(30, 30.0, 12.5);
        // last pts 29/30 s -> floor(0.9667 * 12.5) + 1 = 13
        assert_eq!(out.len(), 13);
        assert_eq!(out[1].pts_ns, 80_000_000);
        // 80 ms -> latest source at or before is frame 2 (66.7 ms)
        assert_eq!(out[1].source_index, 2);
    }

    #[test]
    fn irregular_timestamps() {
        let pts = [0i64, 10, 500_000_000, 510_000_000, 2_000_000_000];
        let src = pts.iter().enumerate().map(|(i, &p)| {
            Ok(Frame {
                width: 1,
                height: 1,
                data: vec![0; 3],
                pts_ns: p,
                source_index: i as u64,
            })
        });
        let out: Vec<_> = Resample::new(src, 2.0)
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        let idx: Vec<u64> = out.iter().map(|f| f.source_index).collect();
        assert_eq!(idx, vec![0, 2, 3, 3, 4]);
    }

    #[test]
    fn errors_are_forwarded_once() {
        let src = vec![
            Ok(Frame {
                width: 1,
                height: 1,
                data: vec![0; 3],
                pts_ns: 0,
                source_index: 0,
            }),
            Err(Error::invalid("boom")),
        ];
        let mut r = Resample::new(src.into_iter(), 10.0).unwrap();
        assert_eq!(r.next().unwrap().unwrap().source_index, 0);
        assert!(r.next().unwrap().is_err());
        assert!(r.next().is_none());
    }

    #[test]
    fn empty_and_bad_fps() {
        assert!(run(0, 10.0, 5.0).is_empty());
        assert!(Resample::new(source(1, 1.0), 0.0).is_err());
        assert!(Resample::new(source(1, 1.0), f64::NAN).is_err());
        assert_eq!(run(1, 10.0, 5.0).len(), 1);
    }
}
