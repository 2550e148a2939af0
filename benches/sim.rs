//! One 1 ms simulator step of the humanoid standing on its 8 sole corners with the door held
//! (spherical joint at the right hand), under a posture PD. Also the step without the door, and
//! with the door pushed by 15 N·m (≈ 20 N at the hand), where some lightly loaded sole corners
//! reach their friction cone so the all-stick direct solve is rejected and Gauss–Seidel runs.

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::DVector;
use upc::sim::{PosturePd, SimConfig, humanoid_scene};

fn bench_step(c: &mut Criterion) {
    for door in [true, false] {
        let mut config = SimConfig::embedded().expect("embedded config");
        config.door = door;
        let scene = humanoid_scene(&config, None).expect("scene");
        let mut w = scene.world;
        let pd = PosturePd::standing(w.robot(), &scene.q_home, &scene.carrying).expect("pd");
        let mut tau = DVector::zeros(w.n_actuated());
        // Settle into steady contact first (warm start as in a running simulation).
        for _ in 0..500 {
            pd.torques(w.q(), w.v(), &mut tau);
            w.step(&tau, 0.0).expect("step");
        }
        let name = if door {
            "sim_step_humanoid_8_contacts_door"
        } else {
            "sim_step_humanoid_8_contacts"
        };
        c.bench_function(name, |b| {
            b.iter(|| {
                pd.torques(w.q(), w.v(), &mut tau);
                std::hint::black_box(w.step(&tau, -2.0).expect("step"))
            })
        });
    }
    let config = SimConfig::embedded().expect("embedded config");
    let scene = humanoid_scene(&config, None).expect("scene");
    let mut w = scene.world;
    let pd = PosturePd::standing(w.robot(), &scene.q_home, &scene.carrying).expect("pd");
    let mut tau = DVector::zeros(w.n_actuated());
    let mut direct = 0;
    for _ in 0..500 {
        pd.torques(w.q(), w.v(), &mut tau);
        let rep = w.step(&tau, -15.0).expect("step");
        direct += usize::from(rep.solver_iterations == 0);
    }
    eprintln!("door pushed: direct solve in {direct} of the 500 settling steps");
    c.bench_function("sim_step_humanoid_8_contacts_door_pushed", |b| {
        b.iter(|| {
            pd.torques(w.q(), w.v(), &mut tau);
            std::hint::black_box(w.step(&tau, -15.0).expect("step"))
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .sample_size(50)
        .warm_up_time(std::time::Duration::from_millis(500))
        .measurement_time(std::time::Duration::from_secs(3));
    targets = bench_step
}
criterion_main!(benches);
