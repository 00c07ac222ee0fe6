//! The all-reduce of a model's gradients bucket by bucket. The gradient tensors, listed in one order that every
//! rank shares (the module's parameter order), are grouped into consecutive buckets of at most a given number
//! of values; each bucket is copied to the host, summed over the ranks and handed back tensor by tensor. The
//! host never holds more than one bucket (or one tensor larger than a bucket) and its send copy, so a 1.3B-
//! parameter model does not need a second full set of gradients in memory.

use std::ops::Range;

use crate::error::CollectiveError;
use crate::group::ProcessGroup;

/// The default bucket: 16 Mi values (64 MiB of `f32`).
pub const DEFAULT_BUCKET_VALUES: usize = 16 << 20;

/// Consecutive tensors grouped into buckets.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BucketPlan {
    /// Each bucket's tensors, as a range of positions in the list.
    buckets: Vec<Range<usize>>,
}

impl BucketPlan {
    /// Buckets of tensors with `lengths` values each (in the shared order), each bucket holding at most
    /// `max_values` values; a tensor larger than that is a bucket of its own.
    pub fn new(lengths: &[usize], max_values: usize) -> Result<Self, CollectiveError> {
        if max_values == 0 {
            return Err(CollectiveError::EmptyBucket);
        }
        let mut buckets = Vec::new();
        let (mut start, mut filled) = (0, 0);
        for (index, &length) in lengths.iter().enumerate() {
            if index > start && filled + length > max_values {
                buckets.push(start..index);
                (start, filled) = (index, 0);
            }
            filled += length;
        }
        if start < lengths.len() {
            buckets.push(start..lengths.len());
        }
        Ok(Self { buckets })
    }

    /// The buckets, in order.
    pub fn buckets(&self) -> &[Range<usize>] {
        &self.buckets
    }
}

/// Sums tensors over the ranks of `group` bucket by bucket: `read(i)` gives tensor `i`'s values on the host,
/// `write(i, values)` takes its sum back. With a group of one, nothing is read or written.
pub fn all_reduce_bucketed(
    group: &ProcessGroup,
    lengths: &[usize],
    max_values: usize,
    mut read: impl FnMut(usize) -> Vec<f32>,
    mut write: impl FnMut(usize, &[f32]),
) -> Result<(), CollectiveError> {
    if group.size() == 1 {
        return Ok(());
    }
    for bucket in BucketPlan::new(lengths, max_values)?.buckets() {
        let mut values: Vec<f32> = Vec::with_capacity(bucket.clone().map(|i| lengths[i]).sum());
        for index in bucket.clone() {
            values.extend(read(index));
        }
        group.all_reduce_sum(&mut values)?;
        let mut offset = 0;
        for index in bucket.clone() {
            write(index, &values[offset..offset + lengths[index]]);
            offset += lengths[index];
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn consecutive_tensors_fill_buckets_up_to_the_limit() {
        let plan = BucketPlan::new(&[3, 4, 2, 10, 1, 1], 8).unwrap();
        assert_eq!(plan.buckets(), &[0..2, 2..3, 3..4, 4..6]);
    }

    #[test]
    fn every_tensor_is_in_exactly_one_bucket_in_order() {
        let lengths: Vec<usize> = (0..50).map(|i| (i * 37) % 23 + 1).collect();
        for limit in [1, 5, 23, 64, 10_000] {
            let plan = BucketPlan::new(&lengths, limit).unwrap();
            let flat: Vec<usize> = plan.buckets().iter().flat_map(Clone::clone).collect();
            assert_eq!(flat, (0..lengths.len()).collect::<Vec<_>>());
            for bucket in plan.buckets() {
                let total: usize = bucket.clone().map(|i| lengths[i]).sum();
                assert!(total <= limit || bucket.len() == 1, "bucket {bucket:?} holds {total} > {limit}");
            }
        }
    }

    #[test]
    fn a_zero_bucket_is_refused() {
        assert!(matches!(BucketPlan::new(&[1], 0), Err(CollectiveError::EmptyBucket)));
    }

    #[test]
    fn a_group_of_one_leaves_the_gradients_alone() {
        let mut touched = false;
        all_reduce_bucketed(&ProcessGroup::Single, &[2, 3], 4, |_| vec![1.0; 3], |_, _| touched = true).unwrap();
        assert!(!touched);
    }
}
