//! The integration tests, one binary: each module is a file of tests/ on one subject (a
//! scenario, a file format, the command line). One binary links the engine once where a binary a
//! file linked it 51 times (most of the tests' build time on a 2-core machine).
//!
//! `cargo test --workspace` runs them with the rest; `cargo test --test integration NAME` runs
//! the tests whose path contains NAME (a module, `mpi::`, or a test's name). The GPU, MPI and
//! VTKHDF modules build with their features (`--features gpu`, ...).

mod common;

mod bodies_periodic;
mod body_families;
mod capsules;
mod checkpoints;
mod chung_ooi;
mod cli;
mod dem_checkpoint;
mod dem_clumps;
mod dem_console;
mod dem_contacts;
mod dem_determinism;
mod dem_energy;
mod dem_mesh_walls;
mod dem_periodic;
mod dem_repose;
mod dem_repose_scripts;
mod dem_silo;
mod dem_stability;
mod dem_triaxial;
mod dem_voids;
mod durability;
mod element_test;
mod gpu;
mod limits;
mod mpi;
mod mpm_bouncing_cube;
mod mpm_checkpoint;
mod mpm_column_collapse;
mod mpm_conservation;
mod mpm_embankment;
mod mpm_fidelity;
mod mpm_friction;
mod mpm_gmsh;
mod mpm_point_traction;
mod mpm_prescribed_velocity;
mod mpm_self_weight;
mod mpm_set_material;
mod mpm_traction;
mod mpmxdem;
mod mpmxdem_adaptive;
mod mpmxdem_scripts;
mod plugins;
mod potential_particles;
mod potential_walls;
mod repl;
mod repl_terminal;
mod script_background;
mod script_errors;
mod script_law;
mod script_outputs;
mod signals;
mod tutorials;
mod vtkhdf;
mod yade_comparison;
