//! How dynamic Gaussians move between the inputs, owned in one place: the setting ([`DynamicMotion`], the
//! `[render] dynamic_motion` of a configuration), what it demands of a model ([`DynamicMotion::in_effect`],
//! [`DynamicMotion::flow_head_mismatch`]) and what it needs done before assembly
//! ([`PixelGaussians::with_motion_found`]: the moving objects found, or the flow head run). Assembly
//! ([`crate::assemble`]) then moves the Gaussians as it says; evaluation and benchmarks name its variants.

use burn::tensor::Tensor;
use dggt_flow_head::FlowHead;
use dggt_instances::InstanceSettings;

use crate::error::SceneError;
use crate::pixels::PixelGaussians;

/// How a dynamic Gaussian moves from the time of the view it came from to the target time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DynamicMotion {
    /// Held where it was predicted, even when the model predicts velocities (the reference every moving
    /// source is scored against).
    Held,
    /// By its predicted velocity when the model predicts one, held where it was predicted otherwise.
    #[default]
    Velocity,
    /// Rigidly along its object's trajectory when it belongs to one of the instances found
    /// ([`PixelGaussians::with_instances`]; means and rotations move, scales and colours do not); as under
    /// `Velocity` otherwise. A target at the view's own time leaves every Gaussian exactly where it was.
    Instances,
    /// Along the learnt scene flow ([`PixelGaussians::with_learnt_flow`]): its learnt displacement to the
    /// neighbouring input toward the target, times the fraction of that step the target has reached; held where
    /// none was learnt and outside the inputs' span. Predicted velocities are not used.
    Learnt,
}

impl DynamicMotion {
    pub const ALL: [DynamicMotion; 4] = [Self::Held, Self::Velocity, Self::Instances, Self::Learnt];

    /// How a model's dynamic Gaussians actually move under this setting: [`Self::Velocity`] holds them when the
    /// model predicts no velocities (`predicts_velocity` false); every other setting is what it says.
    pub fn in_effect(self, predicts_velocity: bool) -> Self {
        match self {
            Self::Velocity if !predicts_velocity => Self::Held,
            other => other,
        }
    }

    /// `held`, `velocity`, `instances` or `learnt`, as in configurations.
    pub fn name(self) -> &'static str {
        match self {
            Self::Held => "held",
            Self::Velocity => "velocity",
            Self::Instances => "instances",
            Self::Learnt => "learnt",
        }
    }
}

/// Why a [`DynamicMotion`] setting and a model's flow head do not go together.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FlowHeadMismatch {
    /// [`DynamicMotion::Learnt`] without a flow head: there is no flow to move along.
    LearntWithoutHead,
    /// A flow head under another setting: it learns from renders along its flow, which it would never get.
    HeadWithoutLearnt,
}

impl DynamicMotion {
    /// How this setting and a model with or without a flow head disagree, if they do.
    pub fn flow_head_mismatch(self, has_flow_head: bool) -> Option<FlowHeadMismatch> {
        match (self == Self::Learnt, has_flow_head) {
            (true, false) => Some(FlowHeadMismatch::LearntWithoutHead),
            (false, true) => Some(FlowHeadMismatch::HeadWithoutLearnt),
            _ => None,
        }
    }
}

impl PixelGaussians {
    /// What `motion` needs before assembly: [`DynamicMotion::Instances`] finds the moving objects (as
    /// `instances` says), [`DynamicMotion::Learnt`] runs the flow head on `flow` (the head and the Gaussian head's
    /// feature maps; an error without them); the others need nothing.
    pub fn with_motion_found(
        self,
        motion: DynamicMotion,
        instances: &InstanceSettings,
        flow: Option<(&FlowHead, &[Tensor<4>])>,
    ) -> Result<Self, SceneError> {
        match motion {
            DynamicMotion::Instances => self.with_instances(instances),
            DynamicMotion::Learnt => match flow {
                Some((head, features)) => self.with_learnt_flow(head, features),
                None => Err(SceneError::NoFlowHead),
            },
            DynamicMotion::Velocity | DynamicMotion::Held => Ok(self),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn velocity_without_predicted_velocities_holds_and_the_flow_head_goes_with_learnt_motion_only() {
        assert_eq!(DynamicMotion::Velocity.in_effect(false), DynamicMotion::Held);
        for motion in DynamicMotion::ALL {
            assert_eq!(motion.in_effect(true), motion);
        }
        assert_eq!(DynamicMotion::Instances.in_effect(false), DynamicMotion::Instances);
        assert_eq!(DynamicMotion::Learnt.flow_head_mismatch(false), Some(FlowHeadMismatch::LearntWithoutHead));
        assert_eq!(DynamicMotion::Held.flow_head_mismatch(true), Some(FlowHeadMismatch::HeadWithoutLearnt));
        assert_eq!(DynamicMotion::Learnt.flow_head_mismatch(true), None);
        assert_eq!(DynamicMotion::Velocity.flow_head_mismatch(false), None);
    }
}
