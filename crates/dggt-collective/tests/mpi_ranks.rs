//! Two MPI ranks on this machine (`mpirun -np 2`, Open MPI or MPICH from the distribution's packages): sums
//! over the ranks, bucket by bucket, equal the sums computed here, and ranks that disagree on a buffer's length
//! all fail instead of waiting for each other.
//!
//! The parent test starts the launcher on this test binary's `rank_body`, which is ignored in a plain run (it
//! only makes sense as one of two ranks) and checks that both ranks ran it and reported success.

use dggt_collective::{CollectiveError, ProcessGroup, all_reduce_bucketed};

#[test]
fn two_ranks_sum_their_gradients_bucket_by_bucket() {
    let program = std::env::current_exe().expect("the test binary's path");
    let output = dggt_test_data::mpi_launcher(2, program)
        .args(["--exact", "rank_body", "--ignored", "--nocapture", "--test-threads", "1"])
        .output()
        .expect("mpirun runs (install openmpi-bin and libopenmpi-dev)");
    let text = format!("{}{}", String::from_utf8_lossy(&output.stdout), String::from_utf8_lossy(&output.stderr));
    assert!(output.status.success(), "the two ranks failed:\n{text}");
    for rank in 0..2 {
        assert!(text.contains(&format!("rank {rank} of 2: sums ok")), "rank {rank} did not report:\n{text}");
    }
}

#[test]
#[ignore = "one rank of the MPI job that `two_ranks_sum_their_gradients_bucket_by_bucket` launches"]
fn rank_body() {
    let group = ProcessGroup::from_environment().expect("joins the MPI world");
    let (rank, size) = (group.rank(), group.size());
    assert_eq!(size, 2, "launched as two ranks");

    // Tensor i of rank r holds values (r + 1) * (i + 1) + k / 8 at position k.
    let lengths = [3, 5, 100, 1, 17];
    let value = |r: usize, i: usize, k: usize| (r + 1) as f32 * (i + 1) as f32 + k as f32 / 8.0;
    let mut sums: Vec<Vec<f32>> = lengths.iter().map(|&n| vec![f32::NAN; n]).collect();
    all_reduce_bucketed(
        &group,
        &lengths,
        8,
        |i| (0..lengths[i]).map(|k| value(rank, i, k)).collect(),
        |i, values| sums[i].copy_from_slice(values),
    )
    .expect("the bucketed sum");
    for (i, sum) in sums.iter().enumerate() {
        for (k, &got) in sum.iter().enumerate() {
            let expected = value(0, i, k) + value(1, i, k);
            assert_eq!(got, expected, "tensor {i} value {k}");
        }
    }

    // A length that differs between the ranks fails on both.
    let mut uneven = vec![1.0f32; 4 + rank];
    let error = group.all_reduce_sum(&mut uneven).expect_err("lengths 4 and 5 cannot be summed");
    assert!(matches!(error, CollectiveError::SizeMismatch { smallest: 4, largest: 5, .. }), "{error}");

    let mut losses = [0.25 * (rank + 1) as f64, 1e-12];
    group.all_reduce_sum_f64(&mut losses).expect("the f64 sum");
    assert_eq!(losses, [0.75, 2e-12]);

    assert_eq!(group.broadcast_u64(41 + rank as u64), 41, "rank 0's value everywhere");
    // 128 bytes, the size of an NCCL id, each different per rank before the broadcast.
    let mut bytes: Vec<u8> = (0..128).map(|k| (k * 3 + rank * 101) as u8).collect();
    group.broadcast_bytes(&mut bytes);
    assert_eq!(bytes, (0..128).map(|k| (k * 3) as u8).collect::<Vec<_>>(), "rank 0's bytes everywhere");
    println!("rank {rank} of {size}: sums ok");
}
