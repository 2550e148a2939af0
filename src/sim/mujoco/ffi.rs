//! MuJoCo's C library through the shim of `shim.c` (built and linked by `build.rs`): a model and
//! its data as one owned value, [`Mj`], and the reads and stages the plant uses. Every pointer
//! comes from MuJoCo and lives as long as the `Mj`; arrays are borrowed with the sizes MuJoCo
//! allocated them with.

use std::ffi::{CStr, CString, c_char, c_int};
use std::ptr::NonNull;

#[repr(C)]
struct Raw {
    _opaque: [u8; 0],
}

unsafe extern "C" {
    fn upc_mj_header_version() -> c_int;
    fn upc_mj_library_version() -> c_int;
    fn upc_mj_version_string() -> *const c_char;
    fn upc_mj_load(xml: *const c_char, len: c_int, err: *mut c_char, err_sz: c_int) -> *mut Raw;
    fn upc_mj_free(h: *mut Raw);
    fn upc_mj_timestep(h: *const Raw) -> f64;
    fn upc_mj_nq(h: *const Raw) -> c_int;
    fn upc_mj_nv(h: *const Raw) -> c_int;
    fn upc_mj_nbody(h: *const Raw) -> c_int;
    fn upc_mj_ngeom(h: *const Raw) -> c_int;
    fn upc_mj_nsite(h: *const Raw) -> c_int;
    fn upc_mj_neq(h: *const Raw) -> c_int;
    fn upc_mj_id(h: *const Raw, kind: c_int, name: *const c_char) -> c_int;
    fn upc_mj_jnt_is_free(h: *const Raw, j: c_int) -> c_int;
    fn upc_mj_jnt_qposadr(h: *const Raw, j: c_int) -> c_int;
    fn upc_mj_jnt_dofadr(h: *const Raw, j: c_int) -> c_int;
    fn upc_mj_jnt_bodyid(h: *const Raw, j: c_int) -> c_int;
    fn upc_mj_geom_bodyid(h: *const Raw, g: c_int) -> c_int;
    fn upc_mj_body_parentid(h: *const Raw, b: c_int) -> c_int;
    fn upc_mj_dof_bodyid(h: *const Raw, v: c_int) -> c_int;
    fn upc_mj_qpos(h: *mut Raw) -> *mut f64;
    fn upc_mj_qvel(h: *mut Raw) -> *mut f64;
    fn upc_mj_qfrc_applied(h: *mut Raw) -> *mut f64;
    fn upc_mj_qfrc_bias(h: *const Raw) -> *const f64;
    fn upc_mj_geom_xpos(h: *const Raw) -> *const f64;
    fn upc_mj_site_xpos(h: *const Raw) -> *const f64;
    fn upc_mj_xmat(h: *const Raw) -> *const f64;
    fn upc_mj_subtree_com(h: *const Raw) -> *const f64;
    fn upc_mj_time(h: *const Raw) -> f64;
    fn upc_mj_set_time(h: *mut Raw, t: f64);
    fn upc_mj_solver_niter(h: *const Raw) -> c_int;
    fn upc_mj_diverged(h: *const Raw) -> c_int;
    fn upc_mj_step(h: *mut Raw);
    fn upc_mj_forward(h: *mut Raw);
    fn upc_mj_positions_velocities(h: *mut Raw);
    fn upc_mj_ncon(h: *const Raw) -> c_int;
    fn upc_mj_contact(h: *const Raw, i: c_int, geom: *mut c_int, frame: *mut f64);
    fn upc_mj_contact_force(h: *const Raw, i: c_int, f: *mut f64);
    fn upc_mj_ne(h: *const Raw) -> c_int;
    fn upc_mj_efc_id(h: *const Raw, r: c_int) -> c_int;
    fn upc_mj_efc_force(h: *const Raw, r: c_int) -> f64;
    fn upc_mj_geom_velocity(h: *const Raw, g: c_int, out: *mut f64);
}

/// The kinds of named objects the plant looks up.
#[derive(Clone, Copy, Debug)]
pub enum Obj {
    Joint = 0,
    Body = 1,
    Geom = 2,
    Site = 3,
    Equality = 4,
}

/// A compiled MuJoCo model and its data.
pub struct Mj {
    h: NonNull<Raw>,
    nq: usize,
    nv: usize,
    nbody: usize,
    ngeom: usize,
    nsite: usize,
    neq: usize,
}

// The model and data are owned by this value alone; MuJoCo keeps no thread-local state for them.
unsafe impl Send for Mj {}

impl Drop for Mj {
    fn drop(&mut self) {
        // SAFETY: `h` came from `upc_mj_load` and is freed once, here.
        unsafe { upc_mj_free(self.h.as_ptr()) }
    }
}

/// MuJoCo's version, e.g. `4.0.0`.
pub fn version() -> String {
    // SAFETY: a static string of the library.
    unsafe { CStr::from_ptr(upc_mj_version_string()) }
        .to_string_lossy()
        .into_owned()
}

fn count(n: c_int) -> usize {
    usize::try_from(n).unwrap_or(0)
}

impl Mj {
    /// Compiles an MJCF document.
    pub fn load(xml: &str) -> Result<Mj, String> {
        // SAFETY: plain calls returning ints.
        let (header, library) = unsafe { (upc_mj_header_version(), upc_mj_library_version()) };
        if header != library {
            return Err(format!(
                "MuJoCo library version {library} ≠ header version {header}: rebuild upc \
                 against the installed MuJoCo (scripts/setup.sh, then cargo build)"
            ));
        }
        let len = c_int::try_from(xml.len()).map_err(|_| "MJCF larger than 2 GB".to_string())?;
        let text = CString::new(xml).map_err(|_| "MJCF with a NUL byte".to_string())?;
        let mut err = vec![0 as c_char; 1024];
        // SAFETY: `text` holds `len` bytes; `err` is writable for its length.
        let h = unsafe { upc_mj_load(text.as_ptr(), len, err.as_mut_ptr(), err.len() as c_int) };
        let Some(h) = NonNull::new(h) else {
            // SAFETY: MuJoCo wrote a NUL-terminated message into `err` (zeroed before).
            let msg = unsafe { CStr::from_ptr(err.as_ptr()) };
            return Err(format!("MuJoCo: {}", msg.to_string_lossy()));
        };
        let r = h.as_ptr();
        // SAFETY: `r` is a live model.
        let (nq, nv, nbody, ngeom, nsite, neq) = unsafe {
            (
                upc_mj_nq(r),
                upc_mj_nv(r),
                upc_mj_nbody(r),
                upc_mj_ngeom(r),
                upc_mj_nsite(r),
                upc_mj_neq(r),
            )
        };
        Ok(Mj {
            h,
            nq: count(nq),
            nv: count(nv),
            nbody: count(nbody),
            ngeom: count(ngeom),
            nsite: count(nsite),
            neq: count(neq),
        })
    }

    fn raw(&self) -> *const Raw {
        self.h.as_ptr()
    }
    fn raw_mut(&mut self) -> *mut Raw {
        self.h.as_ptr()
    }

    pub fn timestep(&self) -> f64 {
        // SAFETY: a live model.
        unsafe { upc_mj_timestep(self.raw()) }
    }
    pub fn ngeom(&self) -> usize {
        self.ngeom
    }
    pub fn neq(&self) -> usize {
        self.neq
    }

    /// The id of the named object, if any.
    pub fn id(&self, kind: Obj, name: &str) -> Option<usize> {
        let name = CString::new(name).ok()?;
        // SAFETY: a live model and a NUL-terminated name.
        let i = unsafe { upc_mj_id(self.raw(), kind as c_int, name.as_ptr()) };
        usize::try_from(i).ok()
    }

    /// A joint's type (free or not), qpos address, dof address and body.
    pub fn joint(&self, j: usize) -> (bool, usize, usize, usize) {
        let (r, j) = (self.raw(), j as c_int);
        // SAFETY: `j` is a joint id from `id`.
        unsafe {
            (
                upc_mj_jnt_is_free(r, j) != 0,
                count(upc_mj_jnt_qposadr(r, j)),
                count(upc_mj_jnt_dofadr(r, j)),
                count(upc_mj_jnt_bodyid(r, j)),
            )
        }
    }
    pub fn geom_body(&self, g: usize) -> usize {
        // SAFETY: `g` < ngeom (ids from `id`).
        count(unsafe { upc_mj_geom_bodyid(self.raw(), g as c_int) })
    }
    pub fn body_parent(&self, b: usize) -> usize {
        // SAFETY: `b` < nbody.
        count(unsafe { upc_mj_body_parentid(self.raw(), b as c_int) })
    }
    pub fn dof_body(&self, v: usize) -> usize {
        // SAFETY: `v` < nv.
        count(unsafe { upc_mj_dof_bodyid(self.raw(), v as c_int) })
    }

    pub fn qpos(&self) -> &[f64] {
        // SAFETY: mj_makeData allocated nq values; the borrow ties them to `self`.
        unsafe { std::slice::from_raw_parts(upc_mj_qpos(self.h.as_ptr()), self.nq) }
    }
    pub fn qpos_mut(&mut self) -> &mut [f64] {
        // SAFETY: as `qpos`, exclusively borrowed.
        unsafe { std::slice::from_raw_parts_mut(upc_mj_qpos(self.raw_mut()), self.nq) }
    }
    pub fn qvel(&self) -> &[f64] {
        // SAFETY: nv values.
        unsafe { std::slice::from_raw_parts(upc_mj_qvel(self.h.as_ptr()), self.nv) }
    }
    pub fn qvel_mut(&mut self) -> &mut [f64] {
        // SAFETY: nv values, exclusively borrowed.
        unsafe { std::slice::from_raw_parts_mut(upc_mj_qvel(self.raw_mut()), self.nv) }
    }
    pub fn qfrc_applied_mut(&mut self) -> &mut [f64] {
        // SAFETY: nv values, exclusively borrowed.
        unsafe { std::slice::from_raw_parts_mut(upc_mj_qfrc_applied(self.raw_mut()), self.nv) }
    }
    pub fn qfrc_bias(&self) -> &[f64] {
        // SAFETY: nv values.
        unsafe { std::slice::from_raw_parts(upc_mj_qfrc_bias(self.raw()), self.nv) }
    }
    fn row3(p: *const f64, n: usize, i: usize) -> [f64; 3] {
        assert!(i < n, "MuJoCo object {i} of {n}");
        // SAFETY: `p` has 3n values and i < n.
        let s = unsafe { std::slice::from_raw_parts(p.add(3 * i), 3) };
        [s[0], s[1], s[2]]
    }
    pub fn geom_xpos(&self, g: usize) -> [f64; 3] {
        // SAFETY: a live data.
        Self::row3(unsafe { upc_mj_geom_xpos(self.raw()) }, self.ngeom, g)
    }
    pub fn site_xpos(&self, s: usize) -> [f64; 3] {
        // SAFETY: a live data.
        Self::row3(unsafe { upc_mj_site_xpos(self.raw()) }, self.nsite, s)
    }
    pub fn subtree_com(&self, b: usize) -> [f64; 3] {
        // SAFETY: a live data.
        Self::row3(unsafe { upc_mj_subtree_com(self.raw()) }, self.nbody, b)
    }
    /// A body's orientation, row-major.
    pub fn xmat(&self, b: usize) -> [f64; 9] {
        assert!(b < self.nbody, "MuJoCo body {b} of {}", self.nbody);
        // SAFETY: 9 nbody values, b < nbody.
        let s = unsafe { std::slice::from_raw_parts(upc_mj_xmat(self.raw()).add(9 * b), 9) };
        std::array::from_fn(|k| s[k])
    }
    pub fn time(&self) -> f64 {
        // SAFETY: a live data.
        unsafe { upc_mj_time(self.raw()) }
    }
    pub fn set_time(&mut self, t: f64) {
        // SAFETY: a live data.
        unsafe { upc_mj_set_time(self.raw_mut(), t) }
    }
    pub fn solver_niter(&self) -> u32 {
        // SAFETY: a live data.
        count(unsafe { upc_mj_solver_niter(self.raw()) }) as u32
    }
    /// Whether the last step raised a warning on which MuJoCo resets its data.
    pub fn diverged(&self) -> bool {
        // SAFETY: a live data.
        unsafe { upc_mj_diverged(self.raw()) != 0 }
    }
    pub fn step(&mut self) {
        // SAFETY: a live model and data.
        unsafe { upc_mj_step(self.raw_mut()) }
    }
    pub fn forward(&mut self) {
        // SAFETY: a live model and data.
        unsafe { upc_mj_forward(self.raw_mut()) }
    }
    /// Geometry and velocities of the current state (a step leaves them at its start).
    pub fn positions_velocities(&mut self) {
        // SAFETY: a live model and data.
        unsafe { upc_mj_positions_velocities(self.raw_mut()) }
    }
    pub fn ncon(&self) -> usize {
        // SAFETY: a live data.
        count(unsafe { upc_mj_ncon(self.raw()) })
    }
    /// Contact `i`'s geoms and frame (row 0 the normal, from geom 0 to geom 1).
    pub fn contact(&self, i: usize) -> ([i32; 2], [f64; 9]) {
        assert!(i < self.ncon(), "contact {i}");
        let (mut g, mut f) = ([0 as c_int; 2], [0.0; 9]);
        // SAFETY: i < ncon; the outputs have 2 and 9 slots.
        unsafe { upc_mj_contact(self.raw(), i as c_int, g.as_mut_ptr(), f.as_mut_ptr()) };
        (g, f)
    }
    /// Contact `i`'s force in its frame (normal, two tangents, then torques).
    pub fn contact_force(&self, i: usize) -> [f64; 6] {
        assert!(i < self.ncon(), "contact {i}");
        let mut f = [0.0; 6];
        // SAFETY: i < ncon; 6 slots.
        unsafe { upc_mj_contact_force(self.raw(), i as c_int, f.as_mut_ptr()) };
        f
    }
    /// Equality constraint rows (they come first among the constraint rows).
    pub fn ne(&self) -> usize {
        // SAFETY: a live data.
        count(unsafe { upc_mj_ne(self.raw()) })
    }
    pub fn efc_id(&self, r: usize) -> usize {
        assert!(r < self.ne(), "equality row {r}");
        // SAFETY: r < ne ≤ nefc.
        count(unsafe { upc_mj_efc_id(self.raw(), r as c_int) })
    }
    pub fn efc_force(&self, r: usize) -> f64 {
        assert!(r < self.ne(), "equality row {r}");
        // SAFETY: r < ne ≤ nefc.
        unsafe { upc_mj_efc_force(self.raw(), r as c_int) }
    }
    /// A geom's spatial velocity [angular; linear] in the world frame.
    pub fn geom_velocity(&self, g: usize) -> [f64; 6] {
        assert!(g < self.ngeom, "geom {g}");
        let mut out = [0.0; 6];
        // SAFETY: g < ngeom; 6 slots.
        unsafe { upc_mj_geom_velocity(self.raw(), g as c_int, out.as_mut_ptr()) };
        out
    }
}
