//! `sim.csv` (`--truth-csv`): the plant's ground truth every record period of a lockstep run,
//! one self-describing record a row ([`crate::record`]): each value is put with its column
//! (name, format) in one call, and the header is the record's columns. Its readers go by
//! column name (`crate::estimation`'s accuracies and true margin, the tests).

use std::io::Write;

use super::physics::{Physics, StepReport};
use crate::channels::N_CONTACTS;
use crate::col;
use crate::record::Record;

/// The ground truth after the step `rep` of `world`: the plant's time, centre of mass, ZMP
/// `zmp` and hand force `hand`, the door, the solver's figures, the floating base, the feet.
pub fn truth_record(
    world: &impl Physics,
    rep: &StepReport,
    zmp: [f64; 2],
    hand: [f64; 3],
) -> Record {
    let mut r = Record::default();
    r.put(col!(fixed("t", 4)), world.time());
    r.put(col!(fixed("com_x", 6)), rep.com[0]);
    r.put(col!(fixed("com_y", 6)), rep.com[1]);
    r.put(col!(fixed("com_z", 6)), rep.com[2]);
    r.put(col!(fixed("zmp_x", 6)), zmp[0]);
    r.put(col!(fixed("zmp_y", 6)), zmp[1]);
    r.put(col!(fixed("hand_fx", 4)), hand[0]);
    r.put(col!(fixed("hand_fy", 4)), hand[1]);
    r.put(col!(fixed("hand_fz", 4)), hand[2]);
    r.put(col!(fixed("door_angle", 6)), world.door_angle());
    r.put(col!(fixed("door_torque", 4)), rep.door_torque);
    r.put(col!(sci("loop_error", 3)), rep.loop_error);
    r.put(col!(sci("max_penetration", 3)), rep.max_penetration);
    r.put(col!(sci("max_slip_speed", 3)), rep.max_slip_speed);
    r.put(
        col!(plain("solver_iterations")),
        f64::from(rep.solver_iterations),
    );
    put_base(&mut r, world);
    put_feet(&mut r, world);
    r
}

/// The floating base: position, linear velocity (world) and roll-pitch-yaw, for the base
/// estimator's error (`upc run`).
fn put_base(r: &mut Record, world: &impl Physics) {
    let (q, v) = (world.q(), world.v());
    let rot = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
        q[6], q[3], q[4], q[5],
    ));
    let vel = rot * nalgebra::Vector3::new(v[0], v[1], v[2]);
    let (roll, pitch, yaw) = rot.euler_angles();
    r.put(col!(fixed("base_x", 6)), q[0]);
    r.put(col!(fixed("base_y", 6)), q[1]);
    r.put(col!(fixed("base_z", 6)), q[2]);
    r.put(col!(fixed("base_vx", 6)), vel.x);
    r.put(col!(fixed("base_vy", 6)), vel.y);
    r.put(col!(fixed("base_vz", 6)), vel.z);
    r.put(col!(fixed("base_roll", 6)), roll);
    r.put(col!(fixed("base_pitch", 6)), pitch);
    r.put(col!(fixed("base_yaw", 6)), yaw);
}

/// Each foot's contact points' centroid (x, y), to see the feet creep, and its load (N: its
/// corners' normal forces), for the wrench observer's error.
fn put_feet(r: &mut Record, world: &impl Physics) {
    let mut feet = [[0.0; 2]; 2];
    for (k, p) in world.contact_points().iter().take(N_CONTACTS).enumerate() {
        let f = &mut feet[k / 4];
        (f[0], f[1]) = (f[0] + p.x / 4.0, f[1] + p.y / 4.0);
    }
    let mut load = [0.0; 2];
    for (k, f) in world.contact_forces().iter().take(N_CONTACTS).enumerate() {
        load[k / 4] += f.z;
    }
    r.put(col!(fixed("lfoot_x", 6)), feet[0][0]);
    r.put(col!(fixed("lfoot_y", 6)), feet[0][1]);
    r.put(col!(fixed("rfoot_x", 6)), feet[1][0]);
    r.put(col!(fixed("rfoot_y", 6)), feet[1][1]);
    r.put(col!(fixed("lfoot_fz", 3)), load[0]);
    r.put(col!(fixed("rfoot_fz", 3)), load[1]);
}
/// The row of the ground truth after the step `rep` of `world` ([`truth_record`]), with ZMP
/// `zmp` and hand force `hand`.
pub fn write_truth(
    w: &mut impl Write,
    world: &impl Physics,
    rep: &StepReport,
    zmp: [f64; 2],
    hand: [f64; 3],
) -> std::io::Result<()> {
    truth_record(world, rep, zmp, hand).write_csv_row(w)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The columns and formats `sim.csv` has always had: its readers and the lockstep runs'
    /// byte-identical files depend on them.
    #[test]
    fn the_columns_are_sim_csv_s() {
        let config = crate::sim::SimConfig::embedded().unwrap();
        let world = crate::sim::humanoid_scene(&config, None).unwrap().world;
        let rep = StepReport {
            com: [0.1, -0.2, 0.9],
            loop_error: 1.5e-4,
            solver_iterations: 12,
            door_torque: -3.25,
            ..Default::default()
        };
        let r = truth_record(&world, &rep, [0.01, 0.02], [1.0, -2.0, 3.0]);
        let mut header = Vec::new();
        r.write_csv_header(&mut header).unwrap();
        assert_eq!(
            String::from_utf8(header).unwrap(),
            "t,com_x,com_y,com_z,zmp_x,zmp_y,hand_fx,hand_fy,hand_fz,door_angle,door_torque,\
             loop_error,max_penetration,max_slip_speed,solver_iterations,base_x,base_y,base_z,\
             base_vx,base_vy,base_vz,base_roll,base_pitch,base_yaw,lfoot_x,lfoot_y,rfoot_x,\
             rfoot_y,lfoot_fz,rfoot_fz\n"
        );
        let mut row = Vec::new();
        r.write_csv_row(&mut row).unwrap();
        let row = String::from_utf8(row).unwrap();
        let cells: Vec<&str> = row.trim_end().split(',').collect();
        assert_eq!(cells.len(), 30, "{row}");
        let given = [
            (0, "0.0000"),
            (1, "0.100000"),
            (2, "-0.200000"),
            (3, "0.900000"),
        ];
        let given = given.into_iter().chain([
            (4, "0.010000"),
            (6, "1.0000"),
            (7, "-2.0000"),
            (10, "-3.2500"),
            (11, "1.500e-4"),
            (12, "0.000e0"),
            (14, "12"),
        ]);
        for (k, cell) in given {
            assert_eq!(cells[k], cell, "column {k} of {row}");
        }
        // `{:.6}` everywhere else but the loads' `{:.3}`.
        let decimals = |c: &str| c.split('.').nth(1).map(str::len);
        for k in (15..28).chain([9]) {
            assert_eq!(decimals(cells[k]), Some(6), "column {k} of {row}");
        }
        assert_eq!(
            (decimals(cells[28]), decimals(cells[29])),
            (Some(3), Some(3))
        );
    }
}
