//! Lift's scripted behaviours, and Lift as an [`ArmTask`] for the data commands.

use super::expert::{LiftExpert, LiftFlaws};
use super::sim::{LiftEpisode, LiftInit, LiftSim, STATE_COLUMNS};
use crate::error::ScenarioError;
use crate::robosuite::episode::ArmEpisode;
use crate::robosuite::rollout::{ArmTask, Episode, Perturbation, RandomActions, RunLimits, TaskEpisode, run};
use crate::robosuite::wander::Wander;

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

/// The Lift task for the data commands.
impl ArmTask for LiftSim {
    type Init = LiftInit;
    type Behaviour = LiftBehaviour;

    fn name(&self) -> &'static str {
        "lift"
    }

    fn behaviours(&self) -> &'static [(&'static str, LiftBehaviour)] {
        &LiftBehaviour::ALL
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
        behaviour: LiftBehaviour,
        perturbation: Perturbation,
        limits: RunLimits,
    ) -> Result<LiftEpisodeRecord, ScenarioError> {
        let mut ep = self.reset(seed)?;
        let init = *ep.init();
        let r = if behaviour == LiftBehaviour::Random {
            let mut random = RandomActions::new("lift", seed);
            run(&mut ep, |_| random.action(), perturbation, behaviour.name(), limits)?
        } else {
            let mut expert = LiftExpert::new(behaviour.flaws());
            let mut wander = (behaviour == LiftBehaviour::Explore).then(|| Wander::new("lift", seed));
            let act = |e: &LiftEpisode| {
                let a = expert.act(e);
                wander.as_mut().map_or(a, |w| w.apply(a))
            };
            run(&mut ep, act, perturbation, behaviour.name(), limits)?
        };
        Ok(Episode::new(seed, init, behaviour, r))
    }
}

impl crate::robosuite::task::ArmEngine for LiftSim {
    type Ep = LiftEpisode;

    fn reset_episode(&self, seed: u64) -> Result<LiftEpisode, ScenarioError> {
        self.reset(seed)
    }
}

/// A finished Lift episode.
pub type LiftEpisodeRecord = Episode<LiftInit, LiftBehaviour>;

impl TaskEpisode for LiftEpisode {
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
