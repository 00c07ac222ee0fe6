//! Data parallelism over several devices: one replica of the network and of its optimiser per device, each
//! device training on its own samples every step, the gradients all-reduced, every replica stepped with the same
//! summed gradients so that all stay identical without the weights ever being copied between devices.
//!
//! The gradients are summed on the master ([`Replicas::sum_on_master`]), summed over the processes of the run
//! when it has several ([`rank_gradients`](crate::rank_gradients)), then shared with every device
//! ([`Replicas::share`]). The in-process all-reduce is this crate's own (sum on the first device, then a copy to
//! every other): burn 0.22's collective all-reduce (`burn::tensor::distributed`, which `ExecutionStrategy::ddp`
//! builds on) is implemented only for CUDA devices in one process and panics on the CPU and wgpu backends, and
//! burn 0.22 has no collective across processes or machines.

use burn::module::{Module, ModuleVisitor, Param, ParamId};
use burn::optim::{GradientsAccumulator, GradientsParams};
use burn::tensor::{Device, Tensor};
use dggt_model::Dggt;

use dggt_run::optimizer::{Optimizer, StepOutcome};

/// The network and its optimiser on one device.
pub struct Replica {
    pub device: Device,
    pub model: Dggt,
    pub optimizer: Optimizer,
}

/// One replica per training device; the first is the master that validation and checkpoints read.
pub struct Replicas(Vec<Replica>);

impl Replicas {
    /// Places `model` and `optimizer` (on `devices[0]`) on every device, once.
    pub fn new(model: Dggt, optimizer: Optimizer, devices: &[Device]) -> Self {
        let mut replicas: Vec<Replica> = devices[1..]
            .iter()
            .map(|device| Replica {
                device: device.clone(),
                model: model.clone().fork(device),
                optimizer: optimizer.fork(device),
            })
            .collect();
        replicas.insert(0, Replica { device: devices[0].clone(), model, optimizer });
        Self(replicas)
    }

    pub fn master(&self) -> &Replica {
        &self.0[0]
    }

    pub fn len(&self) -> usize {
        self.0.len()
    }

    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    pub fn iter(&self) -> impl Iterator<Item = &Replica> {
        self.0.iter()
    }

    /// Sums each device's gradients (given in device order) on the master, in device order, so that the sum
    /// does not depend on thread timing.
    pub fn sum_on_master(&self, per_device: Vec<GradientsParams>) -> GradientsParams {
        let master = self.master();
        let mut sum = GradientsAccumulator::<Dggt>::new();
        for grads in per_device {
            sum.accumulate(&master.model, grads.to_device(&master.device, &master.model));
        }
        sum.grads()
    }

    /// The master's gradients `total` on every device, in device order.
    pub fn share(&self, total: GradientsParams) -> Vec<GradientsParams> {
        let mut copies: Vec<GradientsParams> = self.0[1..]
            .iter()
            .map(|replica| {
                let mut copy = CopyTo { from: &total, to: GradientsParams::new(), device: &replica.device };
                replica.model.visit(&mut copy);
                copy.to
            })
            .collect();
        copies.insert(0, total);
        copies
    }

    /// Steps every replica with its copy of the all-reduced gradients at schedule factor `factor`. The outcome
    /// is the master's; every replica takes the same decision (all hold the same weights and moments and see
    /// the same gradients), a rollback included.
    pub fn step(&mut self, grads: Vec<GradientsParams>, factor: f64) -> StepOutcome {
        let mut master_outcome = StepOutcome::NonFiniteGradient;
        for (position, (replica, grads)) in self.0.iter_mut().zip(grads).enumerate() {
            let (model, outcome) = replica.optimizer.step(replica.model.clone(), grads, factor);
            replica.model = model;
            if position == 0 {
                master_outcome = outcome;
            }
        }
        master_outcome
    }
}

/// Copies every gradient of `from` to `device`.
struct CopyTo<'a> {
    from: &'a GradientsParams,
    to: GradientsParams,
    device: &'a Device,
}

impl ModuleVisitor for CopyTo<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let id: ParamId = param.id;
        if let Some(grad) = self.from.get::<D>(id) {
            self.to.register::<D>(id, grad.to_device(self.device));
        }
    }
}
