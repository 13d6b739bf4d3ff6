//! Training utilities burn does not provide in the form DriftWorld needs:
//!
//! - [`clip_global_norm`]: clip the *global* gradient norm (over all parameters at
//!   once, like `torch.nn.utils.clip_grad_norm_`); burn's `GradientClipping::Norm`
//!   clips each parameter separately, which changes the update direction;
//! - [`Ema`]: an exponential moving average of the weights, kept on the inner
//!   (non-autodiff) device, used for every sample the trainer and `rank` draw;
//! - [`warmup_lr`]: linear warm-up from 1e-6, then constant (spec §6).

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::optim::GradientsParams;
use burn::tensor::Tensor;

/// Linear warm-up from 1e-6 to `lr` over `warmup` steps, then constant.
pub fn warmup_lr(step: u64, lr: f64, warmup: u64) -> f64 {
    if step < warmup { 1e-6 + (lr - 1e-6) * step as f64 / warmup as f64 } else { lr }
}

struct NormVisitor<'a> {
    grads: &'a GradientsParams,
    sum: Option<Tensor<1>>,
}

impl ModuleVisitor for NormVisitor<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        if let Some(g) = self.grads.get::<D>(param.id) {
            let sq = g.powf_scalar(2.0).sum(); // [1]
            self.sum = Some(match self.sum.take() {
                Some(s) => s + sq,
                None => sq,
            });
        }
    }
}

struct ScaleVisitor<'a> {
    grads: &'a mut GradientsParams,
    factor: f64,
}

impl ModuleVisitor for ScaleVisitor<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        if let Some(g) = self.grads.remove::<D>(param.id) {
            self.grads.register(param.id, g * self.factor);
        }
    }
}

/// Scales the gradients so that their global L2 norm is at most `max_norm`;
/// returns the norm before clipping.
pub fn clip_global_norm<M: Module>(module: &M, grads: &mut GradientsParams, max_norm: f64) -> f64 {
    let mut v = NormVisitor { grads, sum: None };
    module.visit(&mut v);
    let norm = v.sum.map_or(0.0, |s| f64::from(s.into_scalar::<f32>()).sqrt());
    if norm.is_finite() && norm > max_norm {
        module.visit(&mut ScaleVisitor { grads, factor: max_norm / (norm + 1e-6) });
    }
    norm
}

struct Collect(Vec<Tensor<1>>);

impl ModuleVisitor for Collect {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let t = param.val().inner(); // plain (non-autodiff) values
        let n = t.shape().num_elements();
        self.0.push(t.reshape([n]));
    }
}

struct Lerp {
    theta: std::vec::IntoIter<Tensor<1>>,
    decay: f64,
}

impl ModuleMapper for Lerp {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        match self.theta.next() {
            Some(th) => {
                let decay = self.decay;
                param.map(|e| {
                    let th = th.reshape(e.dims());
                    e * decay + th * (1.0 - decay)
                })
            }
            None => param,
        }
    }
}

/// An exponential moving average of a module's weights: `ema ← decay·ema + (1−decay)·θ`.
pub struct Ema<M> {
    /// The averaged module (inner device).
    pub module: M,
    /// The decay per update.
    pub decay: f64,
}

impl<M: Module> Ema<M> {
    /// Starts from `module`'s current (validation-mode, inner-device) weights.
    pub fn new(module: &M, decay: f64) -> Self {
        Self { module: module.valid(), decay }
    }

    /// One update from the training module's weights (same architecture).
    pub fn update(&mut self, training: &M) {
        let mut c = Collect(Vec::new());
        training.visit(&mut c);
        let module = self.module.clone();
        self.module = module.map(&mut Lerp { theta: c.0.into_iter(), decay: self.decay });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::nn::{Linear, LinearConfig};
    use burn::tensor::Device;

    #[test]
    fn global_norm_clip_scales_all_gradients_together() {
        let device = Device::flex().autodiff();
        let lin: Linear = LinearConfig::new(2, 1).init(&device);
        // loss = 3·(w·x + b) with x = (1, 2): ∂/∂w = (3, 6), ∂/∂b = 3; norm = √(9+36+9) = √54.
        let x = Tensor::<2>::from_floats([[1.0, 2.0]], &device);
        let loss = lin.forward(x).sum() * 3.0;
        let mut grads = GradientsParams::from_grads(loss.backward(), &lin);
        let norm = clip_global_norm(&lin, &mut grads, 1.0);
        assert!((norm - 54f64.sqrt()).abs() < 1e-5, "{norm}");
        let gw: Vec<f32> = grads.get::<2>(lin.weight.id).unwrap().into_data().try_into_vec::<f32>().unwrap();
        let s = 1.0 / 54f32.sqrt();
        assert!((gw[0] - 3.0 * s).abs() < 1e-5 && (gw[1] - 6.0 * s).abs() < 1e-5, "{gw:?}");
        // Below the threshold nothing changes.
        let norm2 = clip_global_norm(&lin, &mut grads, 10.0);
        assert!((norm2 - 1.0).abs() < 1e-4);
    }

    #[test]
    fn ema_moves_towards_the_weights() {
        let device = Device::flex().autodiff();
        let lin: Linear = LinearConfig::new(1, 1).init(&device);
        let mut ema = Ema::new(&lin, 0.9);
        let w0: f32 = ema.module.weight.val().into_scalar();
        let mut moved = lin.clone();
        moved.weight = moved.weight.map(|w| w + 1.0);
        ema.update(&moved);
        // ema = 0.9 w0 + 0.1 (w0 + 1) = w0 + 0.1.
        let w1: f32 = ema.module.weight.val().into_scalar();
        assert!((w1 - (w0 + 0.1)).abs() < 1e-6, "{w0} -> {w1}");
    }

    #[test]
    fn warmup_is_linear_then_constant() {
        assert_eq!(warmup_lr(0, 1e-3, 10), 1e-6);
        // Halfway: 1e-6 + (1e-3 − 1e-6)/2 = 5.005e-4.
        assert!((warmup_lr(5, 1e-3, 10) - 5.005e-4).abs() < 1e-12);
        assert_eq!(warmup_lr(10, 1e-3, 10), 1e-3);
    }
}
