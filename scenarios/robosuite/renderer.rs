//! The agentview camera rendered in this process: one offscreen MuJoCo renderer per thread
//! and image size, and the process-wide lock that lets one thread at a time use Mesa's
//! GL. An episode ([`super::episode`]) renders through it, or through a render worker
//! ([`super::render_pool`]) whose process renders through it in turn.

use std::cell::RefCell;
use std::mem::ManuallyDrop;
use std::sync::Arc;

use mujoco_rs::prelude::*;
use mujoco_rs::renderer::MjRenderer;

use crate::error::ScenarioError;

thread_local! {
    /// One offscreen renderer per thread and image size (GL contexts are not
    /// `Send`). It is never dropped by the thread's exit: tearing a GL context
    /// down from a thread-local destructor, while EGL and Mesa tear themselves
    /// down at process exit, corrupted the heap now and then (seen as a glibc
    /// abort after the results were written). [`release_renderer`] drops it
    /// while the thread is alive; a thread that never calls it leaks one context
    /// until the process ends.
    static RENDERER: RefCell<Option<(usize, ManuallyDrop<MjRenderer>)>> = const { RefCell::new(None) };
}

/// Held while any thread builds, uses or drops its GL context: one thread renders at a
/// time. Mesa's llvmpipe (22.3, Debian's) crashed in `lp_scene_is_resource_referenced`
/// about once in six hours of two-worker runs, with `LP_NUM_THREADS=0` as well, so the
/// race is between the contexts of two application threads on llvmpipe's shared
/// screen, not only with llvmpipe's own rasteriser threads. Physics still steps in
/// parallel; only the render and its read-back wait (2 of every 8 steps in `rank`).
static RENDER_LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// [`RENDER_LOCK`], held even if another thread panicked while holding it (the lock
/// guards no data, only Mesa's calls).
fn render_lock() -> std::sync::MutexGuard<'static, ()> {
    RENDER_LOCK.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Whether this thread holds an agentview renderer (for tests of its release).
#[cfg(test)]
pub(crate) fn holds_renderer() -> bool {
    RENDERER.with(|cell| cell.borrow().is_some())
}

/// Drops this thread's agentview renderer, if it has one. Call it on every
/// thread that rendered, before the thread or the process ends.
pub fn release_renderer() {
    let _gl = render_lock();
    RENDERER.with(|cell| {
        if let Some((_, r)) = cell.borrow_mut().take() {
            drop(ManuallyDrop::into_inner(r));
        }
    });
}

/// Renders robosuite's `agentview` camera, showing only visual geoms (group 1)
/// and no sites, as robosuite's offscreen renderer does by default. A model with
/// other meshes or textures than the last one (another task) gets a fresh GL
/// context from mujoco-rs.
pub(super) fn render_agentview(
    data: &mut MjData<Arc<MjModel>>,
    size: usize,
) -> Result<Vec<u8>, ScenarioError> {
    let err = |e: &dyn std::fmt::Display| ScenarioError::Render { message: e.to_string() };
    let cam = data.model().camera("agentview").map(|c| c.id).ok_or_else(|| err(&"no camera 'agentview'"))?;
    let _gl = render_lock();
    RENDERER.with(|cell| {
        let mut slot = cell.borrow_mut();
        if slot.as_ref().is_none_or(|(s, _)| *s != size) {
            let side = u32::try_from(size).map_err(|e| err(&e))?;
            let mut r = MjRenderer::builder()
                .width(side)
                .height(side)
                .rgb(true)
                .depth(false)
                .camera(MjvCamera::new_fixed(cam))
                .build(data.model())
                .map_err(|e| err(&e))?;
            let o = r.opts_mut();
            o.geomgroup = [0, 1, 0, 0, 0, 0];
            o.sitegroup = [0; 6];
            if let Some((_, old)) = slot.take() {
                drop(ManuallyDrop::into_inner(old));
            }
            *slot = Some((size, ManuallyDrop::new(r)));
        }
        let (_, r) = slot.as_mut().expect("set above");
        r.set_camera(MjvCamera::new_fixed(cam));
        r.sync_data(data).map_err(|e| err(&e))?;
        r.render().map_err(|e| err(&e))?;
        // mujoco-rs hands the rows over top to bottom: the image is upright, as
        // robomimic stores agentview after flipping robosuite's raw (OpenGL-order)
        // observation.
        let rgb = r.rgb_flat().ok_or_else(|| err(&"renderer returned no RGB image"))?;
        Ok(rgb.to_vec())
    })
}
