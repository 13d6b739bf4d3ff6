//! Can's scripted behaviours, and Can as an [`ArmTask`] for the data commands.

use super::expert::{CanExpert, CanFlaws};
use super::sim::{CanEpisode, CanInit, CanSim, STATE_COLUMNS};
use crate::error::ScenarioError;
use crate::robosuite::episode::ArmEpisode;
use crate::robosuite::rollout::{ArmTask, Episode, Perturbation, RandomActions, RunLimits, TaskEpisode, run};
use crate::robosuite::wander::Wander;

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

/// A finished Can episode.
pub type CanEpisodeRecord = Episode<CanInit, CanBehaviour>;

impl crate::robosuite::task::ArmEngine for CanSim {
    type Ep = CanEpisode;

    fn reset_episode(&self, seed: u64) -> Result<CanEpisode, ScenarioError> {
        self.reset(seed)
    }
}

impl TaskEpisode for CanEpisode {
    fn arm(&self) -> &ArmEpisode {
        self.arm()
    }

    fn arm_mut(&mut self) -> &mut ArmEpisode {
        self.arm_mut()
    }

    fn success(&self) -> bool {
        self.success()
    }
}

/// The Can task for the data commands.
impl ArmTask for CanSim {
    type Init = CanInit;
    type Behaviour = CanBehaviour;

    fn name(&self) -> &'static str {
        "can"
    }

    fn behaviours(&self) -> &'static [(&'static str, CanBehaviour)] {
        &CanBehaviour::ALL
    }

    fn state_columns(&self) -> Vec<&'static str> {
        STATE_COLUMNS.to_vec()
    }

    fn max_steps(&self) -> usize {
        self.config().max_steps
    }

    fn config_json(&self) -> serde_json::Value {
        serde_json::to_value(self.config()).unwrap_or_default()
    }

    fn episode(
        &self,
        seed: u64,
        behaviour: CanBehaviour,
        perturbation: Perturbation,
        limits: RunLimits,
    ) -> Result<CanEpisodeRecord, ScenarioError> {
        let mut ep = self.reset(seed)?;
        let init = *ep.init();
        let name = self.behaviour_name(behaviour);
        let r = if behaviour == CanBehaviour::Random {
            let mut random = RandomActions::new("can", seed);
            run(&mut ep, |_| random.action(), perturbation, name, limits)?
        } else {
            let flaws = behaviour.flaws();
            // The can's quadrant is 3; the wrong one is bread's (1), beside it in y.
            let (x, y) = self.config().quadrant(if flaws.wrong_bin { 1 } else { 3 });
            // The quadrant's corner nearest the robot, moved in by the dividers'
            // half thickness (0.01 m), the can's radius (0.033 m) and a margin: the
            // quadrant's centre lies beyond the Panda's reach with the gripper
            // pointing down.
            let inset = 0.01 + 0.033 + 0.017;
            let target = [x[0] + inset, if flaws.wrong_bin { y[1] - inset } else { y[0] + inset }];
            let bin_z = self.config().bin2_pos[2];
            let mut expert = CanExpert::new(target, flaws);
            let mut wander = (behaviour == CanBehaviour::Explore).then(|| Wander::new("can", seed));
            let act = |e: &CanEpisode| {
                let a = expert.act(e.arm(), bin_z);
                wander.as_mut().map_or(a, |w| w.apply(a))
            };
            run(&mut ep, act, perturbation, name, limits)?
        };
        Ok(Episode::new(seed, init, behaviour, r))
    }
}
