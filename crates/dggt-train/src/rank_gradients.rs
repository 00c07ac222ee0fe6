//! The sum of a step's gradients over the ranks of a process group, after each rank has summed its own
//! devices' ([`Replicas::sum_on_master`](crate::replicas::Replicas::sum_on_master)).
//!
//! Every rank lists the network's parameters in the module's own order (the order in which [`Module::visit`]
//! walks its fields, which the code fixes: never a hash map's), so tensor `i` is the same parameter on every
//! rank. The ranks first agree on which parameters have a gradient (one small sum of a presence mask): a
//! parameter that received one on any rank is summed everywhere, a rank without it contributing zeros, as the
//! sum over samples within one process would; one that received none anywhere stays without (AdamW leaves it
//! alone, as in one process). The gradients then travel bucket by bucket ([`GradientTransport`]): through the
//! host ([`all_reduce_bucketed`]), where a read-back failure on any rank fails the step on every rank before a
//! partial sum can be used, or, on CUDA devices in a build with the `nccl` feature, on the device (each bucket
//! concatenated into one device buffer, summed by NCCL and sliced back).

use burn::module::{Module, ModuleVisitor, Param, ParamId};
use burn::optim::GradientsParams;
use burn::tensor::{Device, Shape, Tensor, TensorData};
use dggt_collective::bucket::DEFAULT_BUCKET_VALUES;
#[cfg(feature = "nccl")]
use dggt_collective::{BucketPlan, nccl::NcclCommunicator};
use dggt_collective::{ProcessGroup, all_reduce_bucketed};
use dggt_model::Dggt;
use dggt_model::host::{ReadBackError, host_f32};

use crate::error::TrainError;

/// One trainable parameter's gradient on this rank, flattened.
struct Slot {
    id: ParamId,
    shape: Vec<usize>,
    device: Device,
    grad: Option<Tensor<1>>,
}

impl Slot {
    fn len(&self) -> usize {
        self.shape.iter().product()
    }
}

/// How a step's gradients travel between the ranks; every rank of a run uses the same.
#[derive(Debug)]
pub enum GradientTransport {
    /// Copied to the host bucket by bucket and summed by MPI: CPU and wgpu devices, and builds without NCCL.
    Host,
    /// Summed on the device by NCCL: every rank's gradients on a CUDA device, in a build with `nccl`.
    #[cfg(feature = "nccl")]
    Nccl(NcclCommunicator),
}

impl GradientTransport {
    /// The transport of a run whose gradients are summed on `device` on this rank: NCCL when every rank can use
    /// it (the ranks agree first, so that no rank waits in a communicator the others never join), else the host.
    pub fn agree(group: &ProcessGroup, device: &Device) -> Result<Self, TrainError> {
        if group.size() == 1 {
            return Ok(Self::Host);
        }
        let mut able = [if Self::device_capable(device) { 1.0f32 } else { 0.0 }];
        group.all_reduce_sum(&mut able)?;
        if able[0] < group.size() as f32 {
            return Ok(Self::Host);
        }
        Self::join_device(group, device)
    }

    /// A CUDA device on a machine with NCCL (a CUDA rank without it is told why its gradients go through the
    /// host).
    #[cfg(feature = "nccl")]
    fn device_capable(device: &Device) -> bool {
        use dggt_collective::nccl::{is_cuda, library_present};
        let capable = is_cuda(device) && library_present();
        if is_cuda(device) && !capable {
            tracing::warn!("NCCL (libnccl.so.2) was not found: every rank sums its gradients through host buffers");
        }
        capable
    }

    #[cfg(not(feature = "nccl"))]
    fn device_capable(_device: &Device) -> bool {
        false
    }

    #[cfg(feature = "nccl")]
    fn join_device(group: &ProcessGroup, device: &Device) -> Result<Self, TrainError> {
        let communicator = NcclCommunicator::join(group, device)?;
        tracing::info!(ranks = group.size(), "gradients are summed on the device by NCCL");
        Ok(Self::Nccl(communicator))
    }

    #[cfg(not(feature = "nccl"))]
    fn join_device(_group: &ProcessGroup, _device: &Device) -> Result<Self, TrainError> {
        Ok(Self::Host)
    }
}

/// Sums `grads` (of `model`, on its device) over the ranks of `group` by `transport`; every rank gets the same
/// sum.
pub fn sum_over_ranks(
    group: &ProcessGroup,
    transport: &GradientTransport,
    model: &Dggt,
    grads: GradientsParams,
) -> Result<GradientsParams, TrainError> {
    if group.size() == 1 {
        return Ok(grads);
    }
    let mut take = TakeInOrder { grads, slots: Vec::new() };
    model.visit(&mut take);
    let mut present: Vec<f32> = take.slots.iter().map(|s| if s.grad.is_some() { 1.0 } else { 0.0 }).collect();
    group.all_reduce_sum(&mut present)?;
    let slots: Vec<Slot> =
        take.slots.into_iter().zip(present).filter(|(_, count)| *count > 0.0).map(|(s, _)| s).collect();

    let summed = match transport {
        GradientTransport::Host => sum_through_host(group, &slots)?,
        #[cfg(feature = "nccl")]
        GradientTransport::Nccl(communicator) => sum_on_device(communicator, &slots)?,
    };
    let mut result = GradientsParams::new();
    for (slot, sum) in slots.iter().zip(summed) {
        register(&mut result, slot, sum);
    }
    Ok(result)
}

/// The sums of `slots` through host buckets, one flattened tensor per slot.
fn sum_through_host(group: &ProcessGroup, slots: &[Slot]) -> Result<Vec<Tensor<1>>, TrainError> {
    let lengths: Vec<usize> = slots.iter().map(Slot::len).collect();
    let mut failure: Option<ReadBackError> = None;
    let mut summed: Vec<Option<Tensor<1>>> = (0..slots.len()).map(|_| None).collect();
    all_reduce_bucketed(
        group,
        &lengths,
        DEFAULT_BUCKET_VALUES,
        |i| read(&slots[i], &mut failure),
        |i, values| {
            let data = TensorData::new(values.to_vec(), [values.len()]);
            summed[i] = Some(Tensor::from_data(data, &slots[i].device));
        },
    )?;
    let mut failed = [if failure.is_some() { 1.0f32 } else { 0.0 }];
    group.all_reduce_sum(&mut failed)?;
    if let Some(error) = failure {
        return Err(error.into());
    }
    if failed[0] > 0.0 {
        return Err(TrainError::RankFailed { what: "reading its gradients back from the device" });
    }
    Ok(summed.into_iter().map(|sum| sum.expect("every bucket was written back")).collect())
}

/// The sums of `slots` on the device: each bucket concatenated (zeros where this rank has no gradient), summed
/// by NCCL and sliced back, one flattened tensor per slot.
#[cfg(feature = "nccl")]
fn sum_on_device(communicator: &NcclCommunicator, slots: &[Slot]) -> Result<Vec<Tensor<1>>, TrainError> {
    let lengths: Vec<usize> = slots.iter().map(Slot::len).collect();
    let mut summed = Vec::with_capacity(slots.len());
    for bucket in BucketPlan::new(&lengths, DEFAULT_BUCKET_VALUES)?.buckets() {
        let parts: Vec<Tensor<1>> = slots[bucket.clone()]
            .iter()
            .map(|slot| slot.grad.clone().unwrap_or_else(|| Tensor::zeros([slot.len()], &slot.device)))
            .collect();
        let total = communicator.all_reduce_sum(Tensor::cat(parts, 0))?;
        let mut offset = 0;
        for slot in &slots[bucket.clone()] {
            summed.push(total.clone().narrow(0, offset, slot.len()));
            offset += slot.len();
        }
    }
    Ok(summed)
}

/// Tensor `slot`'s values on the host, or zeros when this rank has no gradient for it (or its read-back failed:
/// the failure is kept and fails the step on every rank once the sums are done).
fn read(slot: &Slot, failure: &mut Option<ReadBackError>) -> Vec<f32> {
    let Some(grad) = &slot.grad else { return vec![0.0; slot.len()] };
    match host_f32(grad.clone(), "a gradient") {
        Ok(values) => values,
        Err(error) => {
            failure.get_or_insert(error);
            vec![0.0; slot.len()]
        }
    }
}

/// Registers `sum` as the gradient of `slot`'s parameter, in the parameter's shape.
fn register(grads: &mut GradientsParams, slot: &Slot, sum: Tensor<1>) {
    macro_rules! as_rank {
        ($($d:literal),*) => {
            match slot.shape.len() {
                $($d => grads.register::<$d>(slot.id, sum.reshape(Shape::from(slot.shape.clone()))),)*
                other => unreachable!("parameters of rank {other} are not in the network"),
            }
        };
    }
    as_rank!(1, 2, 3, 4, 5, 6);
}

/// Takes every gradient out of a [`GradientsParams`] in the module's parameter order, flattened; a parameter
/// without one (frozen, or unused by this rank's samples) gets an empty slot.
struct TakeInOrder {
    grads: GradientsParams,
    slots: Vec<Slot>,
}

impl ModuleVisitor for TakeInOrder {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let value = param.val();
        let shape = value.dims().to_vec();
        let grad = self.grads.remove::<D>(param.id).map(|g| g.reshape([shape.iter().product::<usize>()]));
        // Gradients live on the device without autodiff.
        self.slots.push(Slot { id: param.id, shape, device: value.device().inner(), grad });
    }
}
