//! Copying burn modules' weights into the CPU kernels' plain arrays ([`kernels`]): dense
//! layers, 3×3 convolutions and GroupNorms, as the world model's and the policies' CPU paths
//! build them; and the jitter the kernels' tests compare burn with.

use burn::module::{ModuleMapper, Param};
use burn::nn::conv::Conv2d;
use burn::nn::{GroupNorm, Linear, PaddingConfig2d};
use burn::tensor::{Distribution, Tensor};
use kernels::direct_conv::{Conv3x3, Norm};
use kernels::matrix::Dense;

/// Why a network cannot be run by the direct kernels (a layer they do not support).
#[derive(Debug, thiserror::Error)]
#[error("layer {layer}: {message}")]
pub struct UnsupportedLayer {
    layer: String,
    message: String,
}

impl UnsupportedLayer {
    /// `layer` cannot run on these kernels, because of `message`.
    pub fn new(layer: &str, message: impl Into<String>) -> Self {
        Self { layer: layer.into(), message: message.into() }
    }
}

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

/// The weights of a 3x3, stride-1, padding-1 burn convolution for [`Conv3x3`].
///
/// # Errors
/// [`UnsupportedLayer`] for any other convolution or non-f32 weights.
pub fn conv3x3_of(c: &Conv2d, layer: &str) -> Result<Conv3x3, UnsupportedLayer> {
    let w = conv3x3_weights(c, layer, 1)?;
    Ok(Conv3x3::new(w.cin, w.cout, &w.weight, w.bias.as_deref()))
}

/// A 3x3 convolution's weights as burn holds them.
pub struct ConvWeights {
    /// Input channels.
    pub cin: usize,
    /// Output channels.
    pub cout: usize,
    /// `[cout, cin, 3, 3]`
    pub weight: Vec<f32>,
    /// `[cout]`, where the convolution has one.
    pub bias: Option<Vec<f32>>,
}

/// The weights of a 3x3, padding-1 burn convolution of stride `stride`.
///
/// # Errors
/// [`UnsupportedLayer`] for any other convolution or non-f32 weights.
pub fn conv3x3_weights(c: &Conv2d, layer: &str, stride: usize) -> Result<ConvWeights, UnsupportedLayer> {
    let padded_one = matches!(c.padding, PaddingConfig2d::Explicit(1, 1, 1, 1));
    if c.kernel_size != [3, 3]
        || c.stride != [stride, stride]
        || c.dilation != [1, 1]
        || c.groups != 1
        || !padded_one
    {
        return Err(UnsupportedLayer::new(
            layer,
            format!("only 3x3 convolutions with stride {stride} and padding 1 are supported"),
        ));
    }
    let w = c.weight.val(); // [cout, cin, 3, 3]
    let [cout, cin, _, _] = w.dims();
    let weight = values(w, layer)?;
    let bias = c.bias.as_ref().map(|b| values(b.val(), layer)).transpose()?;
    Ok(ConvWeights { cin, cout, weight, bias })
}

/// A burn GroupNorm's parameters as a [`Norm`].
///
/// # Errors
/// [`UnsupportedLayer`] for non-f32 parameters.
pub fn norm_of(n: &GroupNorm, layer: &str) -> Result<Norm, UnsupportedLayer> {
    let param = |p: &Option<Param<Tensor<1>>>, fill: f32| match p {
        Some(p) => values(p.val(), layer),
        None => Ok(vec![fill; n.num_channels]),
    };
    Ok(Norm {
        groups: n.num_groups,
        gamma: param(&n.gamma, 1.0)?,
        beta: param(&n.beta, 0.0)?,
        eps: n.epsilon,
    })
}
