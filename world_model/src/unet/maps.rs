//! Action maps: each future frame's action drawn as a Gaussian bump at the
//! commanded position, an extra U-Net input channel (not in the paper) that tells
//! the network *where* the agent goes, which FiLM from an action MLP alone
//! learned poorly on this CPU budget.

use burn::tensor::Tensor;

/// Standard deviation of an action map's bump, in world units (the world is
/// 512 wide; the agent's radius is 15).
pub const ACTION_MAP_SIGMA: f32 = 24.0;

/// A Gaussian bump per frame at the action's position, on an `h × w` grid over
/// the 512-unit world (row = y, column = x, as the renderer draws it). Actions
/// are normalised as `a' = 2a/511 − 1`.
///
/// # Shapes
/// `[b, F, 2] -> [b, 1, F, h, w]`
pub fn action_maps(actions: Tensor<3>, h: usize, w: usize) -> Tensor<5> {
    let [b, f, _] = actions.dims();
    let device = actions.device();
    let world = (actions + 1.0) * (511.0 / 2.0); // [b, F, 2] world units
    let axis = |n: usize, dim: usize| {
        let cells = n as f32 / 512.0; // grid cells per world unit
        let centre = world.clone().narrow(2, dim, 1).reshape([b, 1, f, 1, 1]) * cells; // [b, 1, F, 1, 1]
        let grid: Vec<f32> = (0..n).map(|j| j as f32 + 0.5).collect();
        let grid = Tensor::<1>::from_floats(grid.as_slice(), &device);
        let shape = if dim == 0 { [1, 1, 1, 1, n] } else { [1, 1, 1, n, 1] };
        let d = (grid.reshape(shape) - centre) / (ACTION_MAP_SIGMA * cells); // in sigmas
        d.clone() * d
    };
    let (dx, dy) = (axis(w, 0), axis(h, 1)); // [b, 1, F, 1, w], [b, 1, F, h, 1]
    (dx.expand([b, 1, f, h, w]) + dy.expand([b, 1, f, h, w])).mul_scalar(-0.5).exp()
}

#[cfg(test)]
mod tests {
    use burn::module::Module;
    use burn::tensor::Device;

    use super::*;
    use crate::unet::UNetConfig;

    #[test]
    fn action_map_peaks_at_the_actions_cell() {
        let device = Device::flex();
        // World (416, 96) on an 8x8 grid (64 units per cell): column 416/64 - 0.5 = 6,
        // row 96/64 - 0.5 = 1, both at a cell centre, so the bump is exactly 1 there.
        // Normalised: 2·416/511 − 1 and 2·96/511 − 1.
        let a = [2.0 * 416.0 / 511.0 - 1.0, 2.0 * 96.0 / 511.0 - 1.0];
        let act = Tensor::<1>::from_floats(a.as_slice(), &device).reshape([1, 1, 2]);
        let map: Vec<f32> = action_maps(act, 8, 8).into_data().try_to_vec::<f32>().unwrap();
        assert_eq!(map.len(), 64);
        assert!((map[8 + 6] - 1.0).abs() < 1e-5, "{}", map[8 + 6]);
        // One cell (64 units) to the right: exp(−(64/24)²/2) = exp(−3.556) = 0.0286.
        assert!((map[8 + 7] - 0.0286).abs() < 1e-3, "{}", map[8 + 7]);
        // One cell down is the same distance; one diagonal is exp(−7.111) = 0.00082.
        assert!((map[2 * 8 + 6] - 0.0286).abs() < 1e-3);
        assert!((map[2 * 8 + 7] - 0.00082).abs() < 1e-4);
        let max = map.iter().cloned().fold(f32::MIN, f32::max);
        assert_eq!(max, map[8 + 6]);
    }

    #[test]
    fn adding_action_maps_keeps_the_output_then_lets_actions_move_it() {
        let device = Device::flex();
        let cfg = UNetConfig { model_channels: 32, ..UNetConfig::pusht_latent(4) };
        let unet = cfg.init(&device);
        let rand = |s: [usize; 5]| Tensor::<5>::random(s, burn::tensor::Distribution::Default, &device);
        let (noise, hist) = (rand([1, 4, 4, 8, 8]), rand([1, 4, 4, 8, 8]));
        let a = Tensor::<3>::zeros([1, 4, 2], &device);
        let before = unet.forward(noise.clone(), hist.clone(), a.clone(), None, None);
        let widened = unet.with_action_maps();
        let after = widened.forward(noise.clone(), hist.clone(), a.clone(), None, None);
        let diff: f32 = (before - after.clone()).abs().max().into_scalar();
        assert!(diff < 1e-5, "widening changed the output by {diff}");
        // On an autodiff device the widened weight is a trainable leaf.
        let ad = device.clone().autodiff();
        let trained = cfg.init(&ad).with_action_maps();
        let y = trained.forward(noise.clone(), hist.clone(), a.clone(), None, None);
        let grads = burn::optim::GradientsParams::from_grads(y.sum().backward(), &trained);
        assert!(!grads.is_empty());
        // A fresh action-map model has the extra channel and reacts to it.
        let fresh = UNetConfig { action_maps: Some(true), ..cfg }.init(&device);
        assert_eq!(fresh.num_params(), widened.num_params());
        let y1 = fresh.forward(noise.clone(), hist.clone(), a.clone(), None, None);
        let y2 = fresh.forward(noise, hist, a + 0.5, None, None);
        let moved: f32 = (y1 - y2).abs().mean().into_scalar();
        assert!(moved > 1e-4, "actions have no effect ({moved})");
    }
}
