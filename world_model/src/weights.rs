//! Copying burn modules' weights into the CPU kernels' plain arrays
//! ([`kernels`]), and the jitter the kernels' tests compare burn with.

use burn::module::{ModuleMapper, Param};
use burn::nn::Linear;
use burn::tensor::{Distribution, Tensor};
use kernels::matrix::Dense;

use crate::error::UnsupportedLayer;

/// A burn tensor's values as f32, or why not.
pub fn values<const D: usize>(t: Tensor<D>, layer: &str) -> Result<Vec<f32>, UnsupportedLayer> {
    t.into_data().try_to_vec::<f32>().map_err(|e| UnsupportedLayer::new(layer, format!("{e:?}")))
}

/// A bias's values, zeros when the layer has none.
pub fn bias_values(
    b: &Option<Param<Tensor<1>>>,
    n: usize,
    layer: &str,
) -> Result<Vec<f32>, UnsupportedLayer> {
    b.as_ref().map_or(Ok(vec![0.0; n]), |b| values(b.val(), layer))
}

/// Adds N(0, 0.1) to every weight of a module. The kernels' tests compare them with
/// burn on jittered networks, so that init values (GroupNorm's γ = 1 and β = 0, identity
/// temporal convolutions, zero-initialised layers) become distinct and a mis-wired
/// tap, affine or FiLM half shows.
pub struct Jitter;

impl ModuleMapper for Jitter {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        param.map(|t| {
            let noise = Tensor::random(t.shape(), Distribution::Normal(0.0, 0.1), &t.device());
            t + noise
        })
    }
}

/// A burn [`Linear`] as a [`Dense`] layer.
///
/// # Errors
/// [`UnsupportedLayer`] for non-f32 weights.
pub fn dense_of(l: &Linear, layer: &str) -> Result<Dense, UnsupportedLayer> {
    let w = l.weight.val(); // [d_in, d_out]
    let [din, dout] = w.dims();
    Ok(Dense::from_parts(din, dout, values(w, layer)?, bias_values(&l.bias, dout, layer)?))
}
