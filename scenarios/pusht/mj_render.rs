//! MuJoCo's own OpenGL renderer for Push-T (feature `mujoco-render`).
//!
//! Observations normally come from the 2-D [`super::render::Rasterizer`]; this
//! renderer draws the same state through MuJoCo's offscreen renderer (EGL; on a
//! machine without a GPU, Mesa's software driver) with the scene's top-down
//! orthographic camera, flat lighting and the render-only geoms of
//! [`super::physics::mjcf`]. It exists to cross-check the rasteriser visually and
//! numerically, not for speed.

use std::sync::Arc;

use mujoco_rs::prelude::*;
use mujoco_rs::renderer::MjRenderer;

use super::geometry::Pose2;
use super::physics::PushTState;
use super::render::Rasterizer;
use super::rollout::FrameSource;
use crate::error::ScenarioError;

/// Renders Push-T states with MuJoCo (one GL context per renderer; not `Send`).
pub struct MujocoRenderer {
    data: MjData<Arc<MjModel>>,
    renderer: MjRenderer,
    size: usize,
}

impl MujocoRenderer {
    /// A renderer producing `size x size` RGB images.
    ///
    /// # Errors
    /// [`ScenarioError::Render`] when no offscreen GL context can be created
    /// (missing EGL/Mesa: `scripts/setup.sh` installs them).
    pub fn new(model: Arc<MjModel>, size: usize) -> Result<Self, ScenarioError> {
        let err = |e: &dyn std::fmt::Display| ScenarioError::Render { message: e.to_string() };
        let side = u32::try_from(size).map_err(|e| err(&e))?;
        let camera = MjvCamera::new_fixed(0);
        let renderer = MjRenderer::builder()
            .width(side)
            .height(side)
            .rgb(true)
            .depth(false)
            .camera(camera)
            .build(&model)
            .map_err(|e| err(&e))?;
        Ok(Self { data: MjData::new(model), renderer, size })
    }

    /// Renders a state and goal; rows top to bottom follow the world's y axis
    /// (y down), as the rasteriser's do.
    ///
    /// # Errors
    /// [`ScenarioError::Render`] when the GL context fails.
    pub fn render(&mut self, state: &PushTState, goal: &Pose2) -> Result<Vec<u8>, ScenarioError> {
        let err = |e: &dyn std::fmt::Display| ScenarioError::Render { message: e.to_string() };
        {
            let q = self.data.qpos_mut();
            q[0] = state.agent[0];
            q[1] = state.agent[1];
            q[2] = state.block.x;
            q[3] = state.block.y;
            q[4] = state.block.theta;
        }
        let half = goal.theta / 2.0;
        self.data.mocap_pos_mut()[0] = [goal.x, goal.y, 0.0];
        self.data.mocap_quat_mut()[0] = [half.cos(), 0.0, 0.0, half.sin()];
        self.data.forward();
        self.renderer.sync_data(&mut self.data).map_err(|e| err(&e))?;
        self.renderer.render().map_err(|e| err(&e))?;
        let rgb = self.renderer.rgb_flat().ok_or_else(|| err(&"renderer returned no RGB image"))?;
        // OpenGL's first row is the bottom of the image (largest y with this camera): flip.
        let row = self.size * 3;
        let mut out = Vec::with_capacity(rgb.len());
        for r in rgb.chunks_exact(row).rev() {
            out.extend_from_slice(r);
        }
        Ok(out)
    }
}

impl FrameSource for MujocoRenderer {
    fn frame(&mut self, state: &PushTState, goal: &Pose2) -> Result<Vec<u8>, ScenarioError> {
        self.render(state, goal)
    }
}

/// Frames of MuJoCo's renderer and the rasteriser side by side (`2 size x size`),
/// MuJoCo on the left: the visual cross-check of `simulate --renderer mujoco`.
pub struct SideBySide {
    /// MuJoCo's renderer.
    pub mujoco: MujocoRenderer,
    /// The rasteriser at the same size.
    pub raster: Rasterizer,
}

impl FrameSource for SideBySide {
    fn frame(&mut self, state: &PushTState, goal: &Pose2) -> Result<Vec<u8>, ScenarioError> {
        let a = self.mujoco.render(state, goal)?;
        let b = self.raster.render(state, goal);
        let row = self.mujoco.size * 3;
        let mut out = Vec::with_capacity(a.len() * 2);
        for (ra, rb) in a.chunks_exact(row).zip(b.chunks_exact(row)) {
            out.extend_from_slice(ra);
            out.extend_from_slice(rb);
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::super::PushTConfig;
    use super::super::physics::PushTPhysics;
    use super::*;

    #[test]
    fn mujoco_and_raster_images_agree() {
        let cfg = PushTConfig::default();
        let model = PushTPhysics::compile(&cfg).unwrap();
        let mut mj = match MujocoRenderer::new(model, 96) {
            Ok(r) => r,
            // No EGL on this machine: scripts/setup.sh installs it; CI runs setup first.
            Err(e) => panic!("MuJoCo renderer unavailable: {e}"),
        };
        let raster = Rasterizer::new(&cfg);
        for seed in [0, 5] {
            let (state, goal) = super::super::initial_state(&cfg, seed).unwrap();
            let a = mj.render(&state, &goal).unwrap();
            let b = raster.render(&state, &goal);
            // MJ_RENDER_DUMP=DIR writes each pair side by side as a PPM, to look at.
            if let Ok(dir) = std::env::var("MJ_RENDER_DUMP") {
                let mut ppm = b"P6\n192 96\n255\n".to_vec();
                for row in 0..96 {
                    ppm.extend_from_slice(&a[row * 288..(row + 1) * 288]);
                    ppm.extend_from_slice(&b[row * 288..(row + 1) * 288]);
                }
                std::fs::write(format!("{dir}/crosscheck_{seed}.ppm"), ppm).unwrap();
            }
            // Identical scenes drawn by two renderers: antialiasing differs along edges
            // only, so the mean absolute difference per channel stays small.
            let mad = a.iter().zip(&b).map(|(x, y)| f64::from(x.abs_diff(*y))).sum::<f64>() / a.len() as f64;
            assert!(mad < 4.0, "seed {seed}: mean |mujoco - raster| = {mad}");
        }
    }
}
