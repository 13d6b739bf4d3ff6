//! Can's scripted behaviours: the expert, its flawed variants, random actions and the
//! wandering expert, by name.

use super::config::CanConfig;
use super::expert::{CanExpert, CanFlaws};
use crate::robosuite::arm_sim::Actor;
use crate::robosuite::episode::ArmEpisode;

/// The scripted Can behaviours.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CanBehaviour {
    /// The privileged-state expert.
    Expert,
    /// The expert aiming 4 cm beside the can: it closes on nothing or knocks it.
    Miss,
    /// The expert letting go on the way, 0.25 m short of the target (over the wall).
    Drop,
    /// The expert carrying the can to the neighbouring quadrant.
    WrongBin,
    /// The expert coming down beside the can with the gripper closed and shoving it.
    Push,
    /// The expert standing still 15 steps before every phase.
    Hesitate,
    /// Uniform random actions in [−1, 1]⁷, a fresh one every 5 steps.
    Random,
    /// The expert with a smooth random drift on its arm actions and lapses in which
    /// the drift alone drives the arm ([`Wander`]).
    Explore,
}

impl CanBehaviour {
    /// Every behaviour, by name.
    pub const ALL: [(&'static str, CanBehaviour); 8] = [
        ("expert", Self::Expert),
        ("miss", Self::Miss),
        ("drop", Self::Drop),
        ("wrong-bin", Self::WrongBin),
        ("push", Self::Push),
        ("hesitate", Self::Hesitate),
        ("random", Self::Random),
        ("explore", Self::Explore),
    ];

    /// Its actions: the expert with this behaviour's flaws, carrying to its quadrant of `cfg`'s
    /// bin 2 (the drift of `explore` is added by the simulator), or `None` for uniform random
    /// actions.
    pub(super) fn actor(self, cfg: &CanConfig) -> Option<Actor<'static>> {
        if self == Self::Random {
            return None;
        }
        let flaws = self.flaws();
        // The can's quadrant is 3; the wrong one is bread's (1), beside it in y.
        let (x, y) = cfg.quadrant(if flaws.wrong_bin { 1 } else { 3 });
        // The quadrant's corner nearest the robot, moved in by the dividers'
        // half thickness (0.01 m), the can's radius (0.033 m) and a margin: the
        // quadrant's centre lies beyond the Panda's reach with the gripper
        // pointing down.
        let inset = 0.01 + 0.033 + 0.017;
        let target = [x[0] + inset, if flaws.wrong_bin { y[1] - inset } else { y[0] + inset }];
        let bin_z = cfg.bin2_pos[2];
        let mut expert = CanExpert::new(target, flaws);
        Some(Box::new(move |arm: &ArmEpisode| expert.act(arm, bin_z)))
    }

    fn flaws(self) -> CanFlaws {
        match self {
            Self::Miss => CanFlaws { aim_offset: 0.04, ..CanFlaws::default() },
            Self::Drop => CanFlaws { drop_short: 0.25, ..CanFlaws::default() },
            Self::WrongBin => CanFlaws { wrong_bin: true, ..CanFlaws::default() },
            Self::Push => CanFlaws { push: true, ..CanFlaws::default() },
            Self::Hesitate => CanFlaws { hesitate: 15, ..CanFlaws::default() },
            Self::Expert | Self::Random | Self::Explore => CanFlaws::default(),
        }
    }
}
