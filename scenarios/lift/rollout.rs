//! Lift's scripted behaviours: the expert, its flawed variants, random actions and the
//! wandering expert, by name.

use super::expert::{LiftExpert, LiftFlaws};
use crate::robosuite::arm_sim::Actor;
use crate::robosuite::episode::ArmEpisode;

/// The scripted Lift behaviours.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LiftBehaviour {
    /// The privileged-state expert.
    Expert,
    /// The expert aiming 3 cm beside the cube: it closes on nothing.
    Miss,
    /// The expert stopping and opening the gripper once the cube is 0.015 m up,
    /// short of the 0.04 m that counts.
    Drop,
    /// The expert coming down beside the cube with the gripper closed and shoving it.
    Push,
    /// The expert standing still 15 steps before every phase.
    Hesitate,
    /// Uniform random actions in [−1, 1]⁷, a fresh one every 5 steps.
    Random,
    /// The expert with a smooth random drift on its arm actions and lapses in which
    /// the drift alone drives the arm ([`Wander`]): twists, wandering and stray
    /// gripper commands near the cube, as failing learned policies show.
    Explore,
}

impl LiftBehaviour {
    /// Every behaviour, by name.
    pub const ALL: [(&'static str, LiftBehaviour); 7] = [
        ("expert", Self::Expert),
        ("miss", Self::Miss),
        ("drop", Self::Drop),
        ("push", Self::Push),
        ("hesitate", Self::Hesitate),
        ("random", Self::Random),
        ("explore", Self::Explore),
    ];

    /// Parses a name.
    pub fn parse(name: &str) -> Option<Self> {
        Self::ALL.iter().find(|(n, _)| *n == name).map(|(_, b)| *b)
    }

    /// Its name.
    pub fn name(self) -> &'static str {
        Self::ALL.iter().find(|(_, b)| *b == self).map_or("?", |(n, _)| n)
    }

    /// Its actions: the expert with this behaviour's flaws (the drift of `explore` is added
    /// by the simulator), or `None` for uniform random actions.
    pub(super) fn actor(self) -> Option<Actor<'static>> {
        if self == Self::Random {
            return None;
        }
        let mut expert = LiftExpert::new(self.flaws());
        Some(Box::new(move |arm: &ArmEpisode| expert.act(arm)))
    }

    fn flaws(self) -> LiftFlaws {
        match self {
            Self::Miss => LiftFlaws { aim_offset: 0.03, ..LiftFlaws::default() },
            Self::Drop => LiftFlaws { drop_height: 0.015, ..LiftFlaws::default() },
            Self::Push => LiftFlaws { push: true, ..LiftFlaws::default() },
            Self::Hesitate => LiftFlaws { hesitate: 15, ..LiftFlaws::default() },
            Self::Expert | Self::Random | Self::Explore => LiftFlaws::default(),
        }
    }
}
