//! A fresh network is a function of its seed alone: the backend's random generator is one per process, and
//! threads drawing fresh networks of their own at the same time (two runs in one process, tests side by side)
//! must not change which weights a seed gives.

use burn::module::{ModuleVisitor, Param};
use burn::tensor::{Device, Tensor};
use dggt_infer::fresh_model;
use dggt_model::{Dggt, ModelConfig};

fn parameters(model: &Dggt) -> Vec<f32> {
    struct Collect(Vec<f32>);
    impl ModuleVisitor for Collect {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            self.0.extend(param.val().into_data().convert::<f32>().try_into_vec::<f32>().unwrap());
        }
    }
    let mut collect = Collect(Vec::new());
    burn::module::Module::visit(model, &mut collect);
    collect.0
}

#[test]
fn a_fresh_network_depends_on_its_seed_alone_while_other_threads_draw() {
    let device = Device::flex();
    let config = ModelConfig::tiny();
    let draw = |seed: u64| parameters(&fresh_model(&config, None, seed, &device).expect("a fresh tiny network"));
    let alone = [draw(0), draw(1)];
    assert_ne!(alone[0], alone[1], "two seeds give two networks");

    let (threads, rounds) = (4, 3);
    let drawn: Vec<(usize, Vec<Vec<f32>>)> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..threads)
            .map(|thread| scope.spawn(move || (thread % 2, (0..rounds).map(|_| draw((thread % 2) as u64)).collect())))
            .collect();
        handles.into_iter().map(|handle| handle.join().expect("a drawing thread")).collect()
    });
    for (seed, networks) in drawn {
        for (round, network) in networks.iter().enumerate() {
            assert!(
                *network == alone[seed],
                "seed {seed}, round {round}: other weights than the same seed drawn alone"
            );
        }
    }
}
