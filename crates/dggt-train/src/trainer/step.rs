//! One optimiser step: this process's samples run on every device's replica (forward, objective, backward),
//! their gradients summed over the devices and the ranks, the update clipped and applied at the scheduled rate
//! or skipped (a non-finite loss, a loss spike) or rolled back (a non-finite weight), and the step's record.

use std::time::Instant;

use burn::optim::{GradientsAccumulator, GradientsParams};
use burn::tensor::Device;
use dggt_data::LoadedSample;
use dggt_model::Dggt;
use dggt_objective::{DepthFlowMaps, LossTerm, StepBatch};
use dggt_run::compute_pool::on_pool_worker;
use dggt_run::divergence::{self, StepFailure};
use dggt_run::spikes::{self, Spike};

use super::setup::Trainer;
use crate::error::TrainError;
use crate::rank_gradients::sum_over_ranks;
use crate::ranks;
use crate::records::{FailureRecord, StepMeasures, StepRecord};
use crate::replicas::Replica;

impl Trainer {
    /// One optimiser step on `samples` at schedule factor `factor`: returns the step's record. A non-finite
    /// loss or gradient norm skips the step, an update that makes a weight non-finite is rolled back; either
    /// leaves the weights as they were and is counted ([`divergence`]).
    pub fn train_step(
        &mut self,
        samples: &[LoadedSample],
        factor: f64,
        maps: DepthFlowMaps,
    ) -> Result<StepRecord, TrainError> {
        let step = self.state.step;
        let started = Instant::now();
        let outcome = self.accumulate(samples, maps)?;
        // Every rank learns whether any rank's loss was not finite, so that all skip the step together.
        let measures = ranks::sum_measures(&self.group, outcome.as_ref().map(|o| o.measures.clone()))?;
        let mut record =
            StepRecord { step, lr_factor: factor, update: None, measures: None, failure: None, step_s: 0.0 };
        let failure = match (outcome, measures) {
            (Some(_), Some(measures)) if let Some(spike) = self.judge_spike(step, measures.loss) => {
                record.measures = Some(measures);
                Some(StepFailure::LossSpike(spike))
            }
            (Some(outcome), Some(mut measures)) => {
                let update = Instant::now();
                let master = self.replicas.master();
                let total = self.replicas.sum_on_master(outcome.grads);
                let total = sum_over_ranks(&self.group, &self.transport, &master.model, total)?;
                let replicas = &mut self.replicas;
                let stepped = on_pool_worker(|| {
                    let shared = replicas.share(total);
                    replicas.step(shared, factor)
                });
                record.update = stepped.report().map(Into::into);
                measures.stage_seconds.insert("update".into(), update.elapsed().as_secs_f64());
                record.measures = Some(measures);
                StepFailure::of(&stepped)
            }
            _ => Some(StepFailure::NonFiniteLoss),
        };
        record.failure = failure.as_ref().map(FailureRecord::from);
        if let Some(average) = &mut self.average {
            average.fold(&self.replicas.master().model, step + 1);
        }
        record.step_s = started.elapsed().as_secs_f64();
        divergence::count_step(&mut self.state, step, failure.as_ref());
        self.last_failure = failure;
        self.state.step += 1;
        Ok(record)
    }

    /// Whether step `step`'s `loss` is a spike (`optim.skip_loss_spikes`), remembering it for the steps to come.
    /// The pose warm-up's losses (the camera term alone) are neither judged nor remembered: against them every
    /// full loss after the warm-up would be a spike.
    fn judge_spike(&mut self, step: u64, loss: f64) -> Option<Spike> {
        let section = self.config.optim.skip_loss_spikes?;
        if step < self.config.optim.pose_warmup_steps {
            return None;
        }
        let spike = spikes::judge(&self.state.recent_losses, loss, &section);
        spikes::remember(&mut self.state.recent_losses, loss, section.window);
        spike
    }

    /// Loss and gradients of this process's samples of one step: every device takes its own consecutive
    /// `optim.accumulation` samples (on its own thread; a single device on one of rayon's, [`on_pool_worker`])
    /// and sums their gradients; `None` when a loss is not finite. Each loss is scaled by one over the step's
    /// samples on all ranks. The gradients come back per device, in device order, for
    /// [`Replicas::sum_on_master`].
    ///
    /// [`Replicas::sum_on_master`]: crate::replicas::Replicas::sum_on_master
    fn accumulate(&self, samples: &[LoadedSample], maps: DepthFlowMaps) -> Result<Option<StepOutcome>, TrainError> {
        let scale = 1.0 / (samples.len() * self.group.size()) as f64;
        let shares: Vec<&[LoadedSample]> = samples.chunks(samples.len().div_ceil(self.replicas.len())).collect();
        let results: Vec<Result<DeviceShare, TrainError>> = if shares.len() == 1 {
            vec![on_pool_worker(|| self.run_share(self.replicas.master(), shares[0], scale, maps))]
        } else {
            // One thread per device, each sending its own work to the pool.
            std::thread::scope(|scope| {
                let handles: Vec<_> = self
                    .replicas
                    .iter()
                    .zip(&shares)
                    .map(|(replica, share)| scope.spawn(move || self.run_share(replica, share, scale, maps)))
                    .collect();
                handles.into_iter().map(|h| h.join().expect("a training thread panicked")).collect()
            })
        };
        let mut outcome = StepOutcome::default();
        for share in results {
            let share = share?;
            let Some(grads) = share.grads else { return Ok(None) };
            outcome.grads.push(grads);
            for result in share.samples {
                outcome.add(&result, scale);
            }
        }
        Ok(Some(outcome))
    }

    /// Runs `share` on `replica`, summing its gradients on the replica's device.
    fn run_share(
        &self,
        replica: &Replica,
        share: &[LoadedSample],
        scale: f64,
        maps: DepthFlowMaps,
    ) -> Result<DeviceShare, TrainError> {
        let mut sum = GradientsAccumulator::<Dggt>::new();
        let mut samples = Vec::with_capacity(share.len());
        let mut finite = true;
        for sample in share {
            let (result, grads) = self.run_sample(&replica.model, sample, &replica.device, scale, maps)?;
            match grads {
                Some(grads) => sum.accumulate(&replica.model, grads),
                None => finite = false,
            }
            samples.push(result);
        }
        Ok(DeviceShare { grads: finite.then(|| sum.grads()), samples })
    }

    /// Loss and gradients of one sample; no gradients when the loss or the network's output is not finite.
    fn run_sample(
        &self,
        model: &Dggt,
        sample: &LoadedSample,
        device: &Device,
        scale: f64,
        maps: DepthFlowMaps,
    ) -> Result<(SampleResult, Option<GradientsParams>), TrainError> {
        let started = Instant::now();
        let preprocess = &self.config.data.preprocess;
        let batch = StepBatch::new(sample, &sample.scene, preprocess, maps, device)?;
        let prepared = Instant::now();
        let pose_warmup = sample.step < self.config.optim.pose_warmup_steps;
        let loss =
            if pose_warmup { self.objective.pose_loss(model, &batch) } else { self.objective.loss(model, &batch) };
        let loss = match loss {
            Err(error) if error.is_non_finite_output() => {
                tracing::warn!(step = sample.step, %error, "non-finite network output");
                return Ok((SampleResult::non_finite(), None));
            }
            other => other?,
        };
        let evaluated = Instant::now();
        let value = loss.terms.iter().fold(0.0, |sum, (term, v)| sum + v * term.weight(&self.config.loss));
        let grads = if value.is_finite() {
            let gradients = loss.total.mul_scalar(scale).backward();
            Some(GradientsParams::from_grads(gradients, model))
        } else {
            tracing::warn!(step = sample.step, ?loss.terms, "non-finite loss");
            None
        };
        let stages = [
            ("batch", (prepared - started).as_secs_f64()),
            ("forward_and_render", (evaluated - prepared).as_secs_f64()),
            ("backward", evaluated.elapsed().as_secs_f64()),
        ];
        let result = SampleResult {
            loss: value,
            terms: loss.terms,
            target_psnr: loss.target_psnr,
            kept: loss.counts.kept(),
            stages,
        };
        Ok((result, grads))
    }
}

/// What one sample of a step measured.
struct SampleResult {
    loss: f64,
    terms: std::collections::BTreeMap<LossTerm, f64>,
    target_psnr: f64,
    kept: usize,
    stages: [(&'static str, f64); 3],
}

impl SampleResult {
    /// A sample whose network outputs were not finite: no gradients, so the step is skipped.
    fn non_finite() -> Self {
        Self {
            loss: f64::NAN,
            terms: Default::default(),
            target_psnr: f64::NAN,
            kept: 0,
            stages: [("batch", 0.0), ("forward_and_render", 0.0), ("backward", 0.0)],
        }
    }
}

/// One device's part of a step: its summed gradients (`None` when a sample was not finite) and its samples.
struct DeviceShare {
    grads: Option<GradientsParams>,
    samples: Vec<SampleResult>,
}

/// A step's gradients per device and its metrics averaged over the samples.
#[derive(Default)]
struct StepOutcome {
    grads: Vec<GradientsParams>,
    measures: StepMeasures,
}

impl StepOutcome {
    /// Adds one sample's metrics, weighted by `scale` (one over the samples of the step).
    fn add(&mut self, result: &SampleResult, scale: f64) {
        let measures = &mut self.measures;
        measures.loss += result.loss * scale;
        measures.target_psnr += result.target_psnr * scale;
        measures.gaussians_kept += result.kept;
        for (name, value) in &result.terms {
            *measures.terms.entry(name.name().to_string()).or_default() += value * scale;
        }
        for (name, value) in result.stages {
            *measures.stage_seconds.entry(name.to_string()).or_default() += value;
        }
    }
}
