//! One per-pixel interface for everything that turns a pixel's samples into a result: the
//! symmetry [`Estimator`](crate::Estimator), every [baseline](crate::baseline::BaselineMethod)
//! and the [Ward fitter](crate::fit::FitMethod). The whole-stack drivers here and the tiled job
//! of `symframe-job` run any of them the same way, so given the same samples they give the same
//! results.

use rayon::prelude::*;

use crate::stack::Stack;

/// A per-pixel method: what it reads of a pixel's samples, its per-thread buffers, and the
/// result of one pixel.
pub trait PixelMethod: Sync {
    /// Buffers reused from pixel to pixel on one thread.
    type Scratch: Send;
    /// What one pixel yields.
    type Output: Send;
    /// Rows of the image per parallel task of [`run_stack`]: enough work per task to amortise
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
pub struct Worker<M: PixelMethod> {
    scratch: M::Scratch,
    samples: Vec<f32>,
}

impl<M: PixelMethod> Worker<M> {
    /// A worker for `method` on a stack of `n_input` lights.
    pub fn new(method: &M, n_input: usize) -> Self {
        let n = method.lights().map_or(n_input, |l| l.len());
        Self {
            scratch: method.scratch(),
            samples: vec![0.0; n * 3],
        }
    }

    /// Runs `method` at pixel `p`, whose samples `fill(out)` writes in the method's light order.
    pub fn run(&mut self, method: &M, p: usize, fill: impl FnOnce(&mut [f32])) -> M::Output {
        fill(&mut self.samples);
        method.pixel(p, &self.samples, &mut self.scratch)
    }

    /// Runs `method` at pixel `p` given its samples over every input light (a pixel of a
    /// [`Stack`]): read in place when the method reads every light, else gathered.
    pub fn run_all(&mut self, method: &M, p: usize, all: &[f32]) -> M::Output {
        match method.lights() {
            None => method.pixel(p, all, &mut self.scratch),
            Some(lights) => {
                gather(lights, all, &mut self.samples);
                method.pixel(p, &self.samples, &mut self.scratch)
            }
        }
    }
}

/// Runs `method` on every pixel of `stack` (inside `mask` when given; the others get
/// [`PixelMethod::masked`]) in parallel over bands of [`PixelMethod::BAND_ROWS`] rows, and
/// returns the results in row-major order. `progress` is called with the number of pixels
/// finished by each band. The caller checks that the mask has the stack's size.
pub fn run_stack<M: PixelMethod>(
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
pub fn gather(lights: &[usize], all: &[f32], out: &mut [f32]) {
    for (dst, &i) in out.chunks_exact_mut(3).zip(lights) {
        dst.copy_from_slice(&all[i * 3..i * 3 + 3]);
    }
}
