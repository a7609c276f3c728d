//! One per-pixel interface for everything that turns a pixel's samples into a result: the
//! symmetry [`Estimator`](crate::Estimator), every [baseline](crate::baselines::BaselineMethod)
//! and the [Ward fitter](crate::appearance::fit::FitMethod). The whole-stack drivers here and
//! the tiled job of `symframe-job` run any of them the same way, so given the same samples they
//! give the same results.

use rayon::prelude::*;

use crate::stack::Stack;

/// A per-pixel method: what it reads of a pixel's samples, its per-thread buffers, and the
/// result of one pixel.
pub trait PixelMethod: Sync {
    /// Buffers reused from pixel to pixel on one thread.
    type Scratch: Send;
    /// What one pixel yields.
    type Output: Send;
    /// Rows of the image per parallel task of [`Stack::run`]: enough work per task to amortise
    /// scheduling, small enough to balance (cheap methods take wider bands).
    const BAND_ROWS: usize = 2;

    /// The input lights [`PixelMethod::pixel`] reads, in the order it reads them (indices into
    /// the stack's lights); `None`: every light, in input order.
    fn lights(&self) -> Option<&[usize]>;
    /// Fresh buffers for one thread.
    fn scratch(&self) -> Self::Scratch;
    /// The result at pixel `p` (row-major index in the image) from its `samples`: RGB per light
    /// of [`PixelMethod::lights`], NaN where a sample is invalid.
    fn pixel(&self, p: usize, samples: &[f32], scratch: &mut Self::Scratch) -> Self::Output;
    /// The result of a pixel outside the mask (not looked at).
    fn masked(&self) -> Self::Output;
}

/// Per-thread state of a driver: the method's buffers and one pixel's samples in the method's
/// light order.
struct Worker<M: PixelMethod> {
    scratch: M::Scratch,
    samples: Vec<f32>,
}

impl<M: PixelMethod> Worker<M> {
    /// A worker for `method` on a stack of `n_input` lights.
    fn new(method: &M, n_input: usize) -> Self {
        let n = method.lights().map_or(n_input, |l| l.len());
        Self {
            scratch: method.scratch(),
            samples: vec![0.0; n * 3],
        }
    }

    /// Runs `method` at pixel `p` given its samples over every input light (a pixel of a
    /// [`Stack`]): read in place when the method reads every light, else gathered.
    fn run_all(&mut self, method: &M, p: usize, all: &[f32]) -> M::Output {
        match method.lights() {
            None => method.pixel(p, all, &mut self.scratch),
            Some(lights) => {
                gather(lights, all, &mut self.samples);
                method.pixel(p, &self.samples, &mut self.scratch)
            }
        }
    }
}

impl Stack {
    /// Runs `method` on every pixel of this stack (inside `mask` when given; the others get
    /// [`PixelMethod::masked`]) in parallel over bands of [`PixelMethod::BAND_ROWS`] rows, and
    /// returns the results in row-major order. `progress` is called with the number of pixels
    /// finished by each band. The caller checks that the mask has the stack's size
    /// ([`Stack::check_inputs`]).
    pub fn run<M: PixelMethod>(
        &self,
        method: &M,
        mask: Option<&[bool]>,
        progress: &(dyn Fn(usize) + Sync),
    ) -> Vec<M::Output> {
        run_stack(method, self, mask, progress)
    }
}

/// [`Stack::run`], for the crate's drivers.
pub(crate) fn run_stack<M: PixelMethod>(
    method: &M,
    stack: &Stack,
    mask: Option<&[bool]>,
    progress: &(dyn Fn(usize) + Sync),
) -> Vec<M::Output> {
    let (w, h) = (stack.width, stack.height);
    let rows = M::BAND_ROWS.max(1);
    let bands: Vec<Vec<M::Output>> = (0..h.div_ceil(rows))
        .into_par_iter()
        .map_init(
            || Worker::new(method, stack.n_lights),
            |worker, band| {
                let out: Vec<M::Output> = (band * rows * w..((band + 1) * rows).min(h) * w)
                    .map(|p| {
                        if mask.is_some_and(|m| !m[p]) {
                            return method.masked();
                        }
                        worker.run_all(method, p, stack.pixel(p))
                    })
                    .collect();
                progress(out.len());
                out
            },
        )
        .collect();
    bands.into_iter().flatten().collect()
}

/// Copies the RGB samples of lights `lights` (in that order) out of a pixel's samples over
/// every input light.
#[inline]
pub(crate) fn gather(lights: &[usize], all: &[f32], out: &mut [f32]) {
    for (dst, &i) in out.chunks_exact_mut(3).zip(lights) {
        dst.copy_from_slice(&all[i * 3..i * 3 + 3]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::maps::{PixelRecord, PixelSource, PixelStatus};

    /// Reports the pixel index and the samples it was given.
    struct Echo(Option<Vec<usize>>);

    impl PixelMethod for Echo {
        type Scratch = usize;
        type Output = Option<(usize, Vec<f32>)>;
        const BAND_ROWS: usize = 3;

        fn lights(&self) -> Option<&[usize]> {
            self.0.as_deref()
        }
        fn scratch(&self) -> usize {
            0
        }
        fn pixel(&self, p: usize, samples: &[f32], calls: &mut usize) -> Self::Output {
            *calls += 1;
            Some((p, samples.to_vec()))
        }
        fn masked(&self) -> Self::Output {
            None
        }
    }

    /// A 5 x 7 stack of 3 lights whose sample `(p, i, c)` is `100 p + 10 i + c`.
    fn stack() -> Stack {
        let mut s = Stack::zeros(5, 7, 3);
        for (k, v) in s.data.iter_mut().enumerate() {
            let (p, i, c) = (k / 9, k / 3 % 3, k % 3);
            *v = (100 * p + 10 * i + c) as f32;
        }
        s
    }

    #[test]
    fn every_pixel_in_order_with_its_lights_and_the_mask_respected() {
        let stack = stack();
        let mask: Vec<bool> = (0..35).map(|p| p % 4 != 0).collect();
        let done = std::sync::atomic::AtomicUsize::new(0);
        let progress = |n: usize| {
            done.fetch_add(n, std::sync::atomic::Ordering::SeqCst);
        };
        let all = run_stack(&Echo(None), &stack, Some(&mask), &progress);
        let some = run_stack(&Echo(Some(vec![2, 0])), &stack, None, &|_| {});
        assert_eq!(done.into_inner(), 35);
        assert_eq!((all.len(), some.len()), (35, 35));
        for p in 0..35 {
            assert_eq!(all[p].is_none(), p % 4 == 0);
            if let Some((q, samples)) = &all[p] {
                assert_eq!((*q, samples.as_slice()), (p, stack.pixel(p)));
            }
            let base = 100.0 * p as f32;
            let want = [
                base + 20.0,
                base + 21.0,
                base + 22.0,
                base,
                base + 1.0,
                base + 2.0,
            ];
            assert_eq!(some[p], Some((p, want.to_vec())));
        }
    }

    #[test]
    fn sources_have_fixed_codes_names_and_a_legend() {
        for (k, s) in PixelSource::ALL.iter().enumerate() {
            assert_eq!(*s as u8 as usize, k);
            assert_eq!(PixelSource::from_code(k as u8), Some(*s));
            let name = serde_json::to_string(s).unwrap();
            assert_eq!(name, format!("\"{}\"", s.name()));
        }
        assert_eq!(PixelSource::from_code(5), None);
        let legend = PixelSource::legend();
        assert_eq!(legend[0].1, "none");
        assert_eq!(legend[3], (3, "highlight", legend[3].2));
        assert_eq!(legend[4], (4, "lobe", legend[4].2));
        assert!(legend.iter().all(|l| !l.2.is_empty()));
        // A masked record has no source; a baseline's record carries its method's.
        assert_eq!(PixelRecord::MASKED.source, PixelSource::None);
        assert_eq!(PixelRecord::MASKED.status, PixelStatus::Masked);
        use crate::baselines::Baseline;
        assert_eq!(Baseline::Woodham.source(), PixelSource::Lambertian);
        assert_eq!(Baseline::WoodhamRobust.source(), PixelSource::Lambertian);
        assert_eq!(Baseline::MaxReflectance.source(), PixelSource::Highlight);
    }
}
