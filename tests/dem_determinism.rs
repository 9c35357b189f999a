//! The same DEM scene gives bit-identical results on 1 and 2 threads (per-contact forces, then
//! per-particle gathers in a fixed order).

fn deposit(threads: usize) -> (Vec<[f64; 3]>, Vec<[f64; 3]>, usize) {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
    pool.install(|| {
        let mut sim = granite::bench::gravity_deposition(3000).unwrap();
        for _ in 0..1500 {
            sim.step().unwrap();
        }
        (sim.spheres.x.clone(), sim.spheres.w.clone(), sim.pairs.touching_count())
    })
}

#[test]
fn gravity_deposition_is_thread_count_independent() {
    let one = deposit(1);
    let two = deposit(2);
    assert!(one.2 > 1000, "the scene must have contacts by then ({} contacts)", one.2);
    assert!(one.0 == two.0 && one.1 == two.1, "1 and 2 threads differ");
}
