//! Rerun `.rrd` of the simulator's ground truth, written by a logger thread so the stepping loop
//! never waits on it.
//!
//! Entities: `world/robot/<link>` (per-link `Transform3D`; static child `visual_<k>` with the URDF
//! visual's origin and its box / cylinder / sphere / capsule), `world/door/<link>` likewise,
//! `world/contacts/points` and `world/contacts/forces` (arrows, 1 mm per N… scaled 1/500 m/N),
//! `world/zmp`, `world/support_polygon` (convex hull of the loaded corners), `world/hand_force`.
//! Time line `sim_time` (simulated seconds, as in the controller's recording).
//!
//! The loop offers a frame every `record_period`; the frame goes through a bounded channel and
//! is dropped (and counted) if the logger is behind. Frames are recycled: the loop fills one
//! from a pool the logger hands them back to, and the recording is opened on the logger's
//! thread, so no memory passes between the loop and the recording's threads. Why: a thread in
//! the idle class that frees or grows memory of the loop's allocator arena takes that arena's
//! lock, and preempted while holding it, it stalled the real-time loop under load (gdb: up to
//! 0.79 s, the robot silent to the bus and fallen).

use std::path::Path;
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;

use nalgebra::{UnitQuaternion, Vector3};

use crate::dynamics::{Model, SE3};

use super::physics::Physics;

/// Newtons to metres for the force arrows.
const FORCE_SCALE: f32 = 1.0 / 500.0;

/// Frames the logger wrote and dropped.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct RecorderStats {
    pub written: u64,
    pub dropped: u64,
}

struct Frame {
    time: f64,
    robot: Vec<([f32; 3], [f32; 4])>,
    door: Vec<([f32; 3], [f32; 4])>,
    points: Vec<[f32; 3]>,
    forces: Vec<[f32; 3]>,
    hand: [f32; 3],
    hand_force: [f32; 3],
}

/// Frames in flight: the queue to the logger (0.64 s at 100 Hz) and the pool.
const FRAMES: usize = 64;

/// A running logger thread.
pub struct Recorder {
    tx: Option<SyncSender<Frame>>,
    /// Frames the logger is done with, to fill again.
    free: Receiver<Frame>,
    thread: Option<JoinHandle<u64>>,
    robot_links: Vec<(usize, String)>,
    door_links: Vec<(usize, String)>,
    hand_frame: Option<usize>,
    dropped: u64,
}

fn pose(p: &SE3) -> ([f32; 3], [f32; 4]) {
    let q = UnitQuaternion::from_matrix(&p.rot);
    let c = q.quaternion().coords;
    (
        [p.trans.x as f32, p.trans.y as f32, p.trans.z as f32],
        [c.x as f32, c.y as f32, c.z as f32, c.w as f32],
    )
}

/// The model frames that are URDF links with visuals: (frame index, link name).
fn link_frames(model: &Model, urdf: &urdf_rs::Robot) -> Vec<(usize, String)> {
    urdf.links
        .iter()
        .filter(|l| !l.visual.is_empty())
        .filter_map(|l| model.frame_id(&l.name).ok().map(|f| (f, l.name.clone())))
        .collect()
}

fn color_of(urdf: &urdf_rs::Robot, v: &urdf_rs::Visual) -> [u8; 4] {
    let from = |c: &urdf_rs::Color| c.rgba.0.map(|x| (x.clamp(0.0, 1.0) * 255.0) as u8);
    if let Some(m) = &v.material {
        if let Some(c) = &m.color {
            return from(c);
        }
        if let Some(c) = urdf
            .materials
            .iter()
            .find(|g| g.name == m.name)
            .and_then(|g| g.color.as_ref())
        {
            return from(c);
        }
    }
    [180, 180, 190, 255]
}

/// Logs each link's visuals: primitives, and meshes whose file resolves
/// ([`crate::robot::packages::resolve_mesh`], relative paths against `urdf_dir`; a URDF
/// without its mesh files is drawn with what remains; `package://` looked up in `dirs`). Returns
/// how many meshes were not found, and the first of them.
fn log_geometry(
    rec: &rerun::RecordingStream,
    prefix: &str,
    urdf: &urdf_rs::Robot,
    urdf_dir: Option<&Path>,
    dirs: &[std::path::PathBuf],
) -> rerun::RecordingStreamResult<(usize, Option<String>)> {
    let mut missing = 0;
    let mut first = None;
    for link in &urdf.links {
        for (k, v) in link.visual.iter().enumerate() {
            let path = format!("{prefix}/{}/visual_{k}", link.name);
            let o = SE3::from_xyz_rpy(v.origin.xyz.0, v.origin.rpy.0);
            let (t, q) = pose(&o);
            let mut transform =
                rerun::Transform3D::from_translation_rotation(t, rerun::Quaternion::from_xyzw(q));
            if let urdf_rs::Geometry::Mesh { scale: Some(s), .. } = &v.geometry {
                transform = transform.with_scale(s.0.map(|x| x as f32));
            }
            rec.log_static(path.as_str(), &transform)?;
            let [r, g, b, a] = color_of(urdf, v);
            let color = rerun::Color::from_unmultiplied_rgba(r, g, b, a);
            match &v.geometry {
                urdf_rs::Geometry::Box { size } => {
                    let s = size.0.map(|x| x as f32 / 2.0);
                    rec.log_static(
                        path.as_str(),
                        &rerun::Boxes3D::from_half_sizes([s])
                            .with_colors([color])
                            .with_fill_mode(rerun::FillMode::Solid),
                    )?;
                }
                urdf_rs::Geometry::Cylinder { radius, length } => {
                    rec.log_static(
                        path.as_str(),
                        &rerun::Cylinders3D::from_lengths_and_radii(
                            [*length as f32],
                            [*radius as f32],
                        )
                        .with_colors([color])
                        .with_fill_mode(rerun::FillMode::Solid),
                    )?;
                }
                urdf_rs::Geometry::Capsule { radius, length } => {
                    // Rerun's capsule starts at the origin along +z; URDF's is centred.
                    rec.log_static(
                        path.as_str(),
                        &rerun::Capsules3D::from_lengths_and_radii(
                            [*length as f32],
                            [*radius as f32],
                        )
                        .with_translations([[0.0, 0.0, -(*length as f32) / 2.0]])
                        .with_colors([color]),
                    )?;
                }
                urdf_rs::Geometry::Sphere { radius } => {
                    rec.log_static(
                        path.as_str(),
                        &rerun::Ellipsoids3D::from_radii([*radius as f32])
                            .with_colors([color])
                            .with_fill_mode(rerun::FillMode::Solid),
                    )?;
                }
                urdf_rs::Geometry::Mesh { filename, .. } => {
                    let file = crate::robot::packages::resolve_mesh_in(filename, urdf_dir, dirs);
                    match file.map(std::fs::read) {
                        Some(Ok(bytes)) => {
                            let media = filename
                                .to_ascii_lowercase()
                                .ends_with(".stl")
                                .then(rerun::MediaType::stl);
                            rec.log_static(
                                path.as_str(),
                                &rerun::Asset3D::from_file_contents(bytes, media)
                                    .with_albedo_factor(
                                        rerun::datatypes::Rgba32::from_unmultiplied_rgba(
                                            r, g, b, a,
                                        ),
                                    ),
                            )?;
                        }
                        _ => {
                            missing += 1;
                            first.get_or_insert_with(|| filename.clone());
                        }
                    }
                }
            }
        }
    }
    Ok((missing, first))
}

/// Convex hull (counter-clockwise, closed) of 2-D points, by monotone chain.
pub fn convex_hull(points: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut p: Vec<[f64; 2]> = points.to_vec();
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: &[f64; 2], a: &[f64; 2], b: &[f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut hull: Vec<[f64; 2]> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for q in iter {
            while hull.len() >= start + 2
                && cross(&hull[hull.len() - 2], &hull[hull.len() - 1], q) <= 0.0
            {
                hull.pop();
            }
            hull.push(*q);
        }
        hull.pop();
    }
    hull
}

fn write_frame(
    rec: &rerun::RecordingStream,
    f: &Frame,
    robot: &[(usize, String)],
    door: &[(usize, String)],
) -> rerun::RecordingStreamResult<()> {
    rec.set_duration_secs("sim_time", f.time);
    for ((_, name), (t, q)) in robot.iter().zip(&f.robot) {
        rec.log(
            format!("world/robot/{name}"),
            &rerun::Transform3D::from_translation_rotation(*t, rerun::Quaternion::from_xyzw(*q)),
        )?;
    }
    for ((_, name), (t, q)) in door.iter().zip(&f.door) {
        rec.log(
            format!("world/door/{name}"),
            &rerun::Transform3D::from_translation_rotation(*t, rerun::Quaternion::from_xyzw(*q)),
        )?;
    }
    rec.log(
        "world/contacts/points",
        &rerun::Points3D::new(f.points.iter().copied()).with_radii([0.006]),
    )?;
    let loaded: Vec<usize> = (0..f.points.len())
        .filter(|&k| f.forces[k][2] > 1e-3)
        .collect();
    rec.log(
        "world/contacts/forces",
        &rerun::Arrows3D::from_vectors(f.forces.iter().map(|v| v.map(|x| x * FORCE_SCALE)))
            .with_origins(f.points.iter().copied())
            .with_colors([rerun::Color::from_rgb(230, 80, 40)]),
    )?;
    let fz: f32 = loaded.iter().map(|&k| f.forces[k][2]).sum();
    if fz > 1e-3 {
        let cop = loaded.iter().fold([0.0f32; 2], |acc, &k| {
            [
                acc[0] + f.forces[k][2] * f.points[k][0],
                acc[1] + f.forces[k][2] * f.points[k][1],
            ]
        });
        rec.log(
            "world/zmp",
            &rerun::Points3D::new([[cop[0] / fz, cop[1] / fz, 0.0]])
                .with_radii([0.012])
                .with_colors([rerun::Color::from_rgb(40, 200, 60)]),
        )?;
        let pts: Vec<[f64; 2]> = loaded
            .iter()
            .map(|&k| [f.points[k][0] as f64, f.points[k][1] as f64])
            .collect();
        let mut hull = convex_hull(&pts);
        if let Some(first) = hull.first().copied() {
            hull.push(first);
        }
        rec.log(
            "world/support_polygon",
            &rerun::LineStrips3D::new([hull.iter().map(|p| [p[0] as f32, p[1] as f32, 0.0])])
                .with_colors([rerun::Color::from_rgb(40, 120, 230)]),
        )?;
    } else {
        rec.log("world/zmp", &rerun::Clear::flat())?;
        rec.log("world/support_polygon", &rerun::Clear::flat())?;
    }
    rec.log(
        "world/hand_force",
        &rerun::Arrows3D::from_vectors([f.hand_force.map(|x| x * FORCE_SCALE * 5.0)])
            .with_origins([f.hand])
            .with_colors([rerun::Color::from_rgb(200, 40, 200)]),
    )?;
    Ok(())
}

fn logger(
    rec: rerun::RecordingStream,
    rx: Receiver<Frame>,
    free: SyncSender<Frame>,
    robot: Vec<(usize, String)>,
    door: Vec<(usize, String)>,
) -> u64 {
    let mut written = 0;
    let mut failed = false;
    // Polled, not `recv`: see `drain_periodically` (the queue holds 64 frames, 0.64 s).
    crate::realtime::drain_periodically(&rx, std::time::Duration::from_millis(20), |f| {
        match write_frame(&rec, &f, &robot, &door) {
            Ok(()) => written += 1,
            Err(e) if !failed => {
                tracing::warn!("rerun logging failed: {e}");
                failed = true;
            }
            Err(_) => {}
        }
        // Back to the loop's pool (never full: it holds at most the frames there are).
        let _ = free.try_send(f);
    });
    if let Err(e) = rec.flush_blocking() {
        tracing::warn!("rerun flush failed: {e}");
    }
    written
}

/// What the recording draws still: the robot's URDF (and where its meshes are looked up) and
/// the door's.
struct SceneGeometry {
    robot_urdf: urdf_rs::Robot,
    urdf_dir: Option<std::path::PathBuf>,
    name: String,
    door_urdf: Option<urdf_rs::Robot>,
}

impl SceneGeometry {
    /// Logs the world's axes and the robot's and the door's visuals (static).
    fn log(&self, rec: &rerun::RecordingStream) -> rerun::RecordingStreamResult<()> {
        rec.log_static("world", &rerun::ViewCoordinates::RIGHT_HAND_Z_UP())?;
        let urdf_dir = self.urdf_dir.as_deref();
        let dirs = crate::robot::packages::package_search_dirs();
        let (missing, first) = log_geometry(rec, "world/robot", &self.robot_urdf, urdf_dir, &dirs)?;
        if let Some(first) = first {
            let looked: Vec<String> = dirs.iter().map(|d| d.display().to_string()).collect();
            tracing::info!(
                "rerun: {missing} mesh files of `{}` not found, not drawn (the first: {first}); \
                 relative paths are looked up next to the URDF ({}), package:// in [{}] \
                 (ROS_PACKAGE_PATH, AMENT_PREFIX_PATH's share/, UPC_ROBOT_VENV's share/)",
                self.name,
                urdf_dir.map_or("<embedded>".into(), |d| d.display().to_string()),
                looked.join(", ")
            );
        }
        if let Some(door) = &self.door_urdf {
            log_geometry(rec, "world/door", door, None, &[])?;
        }
        Ok(())
    }
}

/// Runs `f` in the idle class when `idle` (threads it starts inherit it: see
/// `realtime::in_background`), else as it is.
fn in_class<T>(idle: bool, f: impl FnOnce() -> T) -> T {
    if idle {
        crate::realtime::in_background(f)
    } else {
        f()
    }
}

impl Recorder {
    /// Opens the `.rrd` and starts the logger thread, which logs the static geometry of the
    /// robot and the door (their URDFs' visuals: primitives, and the meshes whose files
    /// resolve), then the frames. The recording is opened and written on that thread only:
    /// every buffer of it is that thread's or rerun's threads', never the stepping loop's (a
    /// buffer the loop had allocated, grown by rerun's file writer in the idle class, held the
    /// allocator's lock from the loop for up to 0.79 s under load). `idle_threads` (real
    /// time): rerun's threads and the frames' logging run in the idle class
    /// (`realtime::in_background`), the meshes are read at nice 19 (in the idle class, on the
    /// loop's thread, a loaded machine once held a G1's start-up for 13 s).
    pub fn spawn(
        path: &Path,
        recording_id: Option<&str>,
        live: Option<&str>,
        world: &impl Physics,
        robot: &crate::robot::Robot,
        idle_threads: bool,
    ) -> Result<Recorder, Box<dyn std::error::Error + Send + Sync>> {
        let robot_urdf = crate::dynamics::parse_urdf(&robot.urdf)?;
        let robot_links = link_frames(world.robot(), &robot_urdf);
        let (door_urdf, door_links) = match world.door_model() {
            Some(model) => {
                let door_urdf = crate::dynamics::parse_urdf(crate::dynamics::icub_like::DOOR_URDF)?;
                let links = link_frames(model, &door_urdf);
                (Some(door_urdf), links)
            }
            None => (None, Vec::new()),
        };
        let scene = SceneGeometry {
            robot_urdf,
            urdf_dir: robot
                .urdf_path
                .as_deref()
                .and_then(Path::parent)
                .map(Path::to_path_buf),
            name: robot.name().to_string(),
            door_urdf,
        };
        let hand_frame = world.robot().frame_id(&robot.description.hand.frame).ok();
        let (tx, rx) = sync_channel::<Frame>(FRAMES);
        let (free_tx, free) = sync_channel::<Frame>(FRAMES);
        let contacts = world.contact_points().len().max(16);
        for _ in 0..FRAMES {
            let _ = free_tx.try_send(Frame {
                time: 0.0,
                robot: Vec::with_capacity(robot_links.len()),
                door: Vec::with_capacity(door_links.len()),
                points: Vec::with_capacity(contacts),
                forces: Vec::with_capacity(contacts),
                hand: [0.0; 3],
                hand_force: [0.0; 3],
            });
        }
        let (rl, dl) = (robot_links.clone(), door_links.clone());
        let (path, id, live) = (
            path.to_path_buf(),
            recording_id.map(str::to_string),
            live.map(str::to_string),
        );
        let (opened_tx, opened) = sync_channel::<Result<(), String>>(1);
        let thread = std::thread::Builder::new()
            .name("sim-rerun".into())
            .spawn(move || {
                let open = || crate::recording::open(&path, id.as_deref(), live.as_deref());
                let rec = match in_class(idle_threads, open) {
                    Ok(rec) => rec,
                    Err(e) => {
                        let _ = opened_tx.send(Err(e.to_string()));
                        return 0;
                    }
                };
                let _ = opened_tx.send(Ok(()));
                if idle_threads {
                    // The meshes are read beside the loop's first steps: at the lowest normal
                    // priority, not the idle class, which a loaded machine hardly runs.
                    crate::realtime::lower_priority(19);
                }
                if let Err(e) = scene.log(&rec) {
                    tracing::warn!("rerun: the scene's geometry was not logged: {e}");
                }
                in_class(idle_threads, || logger(rec, rx, free_tx, rl, dl))
            })?;
        match opened.recv() {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(e.into()),
            Err(_) => return Err("the recording's thread ended before it opened the file".into()),
        }
        Ok(Recorder {
            tx: Some(tx),
            free,
            thread: Some(thread),
            robot_links,
            door_links,
            hand_frame,
            dropped: 0,
        })
    }

    /// Offers the current state in a frame of the pool; dropped (and counted) if the logger is
    /// behind (the pool is empty). Allocates nothing once the frames have their sizes.
    pub fn offer(&mut self, world: &mut impl Physics, hand_force: &[f64; 3]) {
        let Some(tx) = &self.tx else { return };
        let Ok(mut frame) = self.free.try_recv() else {
            self.dropped += 1;
            return;
        };
        let placements = world.robot_frame_placements();
        frame.robot.clear();
        frame
            .robot
            .extend(self.robot_links.iter().map(|(f, _)| pose(&placements[*f])));
        let hand = self
            .hand_frame
            .map(|f| placements[f].trans)
            .unwrap_or_else(Vector3::zeros);
        frame.door.clear();
        if let Some(p) = world.door_frame_placements() {
            frame
                .door
                .extend(self.door_links.iter().map(|(f, _)| pose(&p[*f])));
        }
        let f32s = |p: &Vector3<f64>| [p.x as f32, p.y as f32, p.z as f32];
        frame.points.clear();
        frame.points.extend(world.contact_points().iter().map(f32s));
        frame.forces.clear();
        frame.forces.extend(world.contact_forces().iter().map(f32s));
        frame.time = world.time();
        frame.hand = f32s(&hand);
        frame.hand_force = hand_force.map(|x| x as f32);
        match tx.try_send(frame) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) => self.dropped += 1,
            Err(TrySendError::Disconnected(_)) => {
                self.tx = None;
            }
        }
    }

    /// Closes the channel, waits for the logger to flush the file.
    pub fn finish(mut self) -> RecorderStats {
        crate::realtime::leave_background();
        self.tx = None;
        let written = self.thread.take().and_then(|t| t.join().ok()).unwrap_or(0);
        RecorderStats {
            written,
            dropped: self.dropped,
        }
    }
}
