//! What robosuite's manipulation scenes share: the asset folder, the scene
//! composer (Panda, mount, gripper, arenas) and the OSC_POSE arm controller.
//!
//! Lift and Can (`crate::lift`, `crate::can`) build on it. Everything follows
//! robosuite 1.5.2 at its default settings, so that a robomimic user recognises
//! the scenes, actions and success checks.

pub mod assets;
pub mod episode;
pub mod linalg;
pub mod osc;
pub mod rollout;
pub mod scene;

#[cfg(test)]
mod tests;
