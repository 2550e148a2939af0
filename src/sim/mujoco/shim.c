/* The few fields of MuJoCo's mjModel / mjData the plant reads, behind functions (their struct
 * layouts are MuJoCo's own, of the headers it was built with): src/sim/mujoco/ffi.rs declares
 * these. No logic here: the plant itself is Rust (src/sim/mujoco/plant.rs). */
#include <string.h>
#include <mujoco/mujoco.h>

typedef struct {
  mjModel* m;
  mjData* d;
} upc_mj;

/* Checks that the library is the one of the headers (their structs must match). */
int upc_mj_header_version(void) { return mjVERSION_HEADER; }
int upc_mj_library_version(void) { return mj_version(); }
const char* upc_mj_version_string(void) { return mj_versionString(); }

/* Compiles an MJCF given as text (no file: a virtual file system of one buffer). NULL on error,
 * with MuJoCo's message in `err`. */
upc_mj* upc_mj_load(const char* xml, int len, char* err, int err_sz) {
  mjVFS vfs;
  mj_defaultVFS(&vfs);
  if (mj_addBufferVFS(&vfs, "scene.xml", xml, len) != 0) {
    strncpy(err, "could not add the scene to MuJoCo's virtual file system", err_sz - 1);
    err[err_sz - 1] = 0;
    mj_deleteVFS(&vfs);
    return NULL;
  }
  mjModel* m = mj_loadXML("scene.xml", &vfs, err, err_sz);
  mj_deleteVFS(&vfs);
  if (!m) return NULL;
  mjData* d = mj_makeData(m);
  if (!d) {
    strncpy(err, "mj_makeData failed", err_sz - 1);
    err[err_sz - 1] = 0;
    mj_deleteModel(m);
    return NULL;
  }
  upc_mj* h = (upc_mj*)mju_malloc(sizeof(upc_mj));
  h->m = m;
  h->d = d;
  return h;
}

void upc_mj_free(upc_mj* h) {
  if (!h) return;
  mj_deleteData(h->d);
  mj_deleteModel(h->m);
  mju_free(h);
}

/* Model: sizes and the ids, addresses and trees the plant maps once. */
double upc_mj_timestep(const upc_mj* h) { return h->m->opt.timestep; }
int upc_mj_nq(const upc_mj* h) { return h->m->nq; }
int upc_mj_nv(const upc_mj* h) { return h->m->nv; }
int upc_mj_nbody(const upc_mj* h) { return h->m->nbody; }
int upc_mj_ngeom(const upc_mj* h) { return h->m->ngeom; }
int upc_mj_nsite(const upc_mj* h) { return h->m->nsite; }
int upc_mj_neq(const upc_mj* h) { return h->m->neq; }

/* kind: 0 joint, 1 body, 2 geom, 3 site, 4 equality. -1 if there is no such object. */
int upc_mj_id(const upc_mj* h, int kind, const char* name) {
  static const int types[] = {mjOBJ_JOINT, mjOBJ_BODY, mjOBJ_GEOM, mjOBJ_SITE, mjOBJ_EQUALITY};
  if (kind < 0 || kind > 4) return -1;
  return mj_name2id(h->m, types[kind], name);
}
int upc_mj_jnt_is_free(const upc_mj* h, int j) { return h->m->jnt_type[j] == mjJNT_FREE; }
int upc_mj_jnt_qposadr(const upc_mj* h, int j) { return h->m->jnt_qposadr[j]; }
int upc_mj_jnt_dofadr(const upc_mj* h, int j) { return h->m->jnt_dofadr[j]; }
int upc_mj_jnt_bodyid(const upc_mj* h, int j) { return h->m->jnt_bodyid[j]; }
int upc_mj_geom_bodyid(const upc_mj* h, int g) { return h->m->geom_bodyid[g]; }
int upc_mj_body_parentid(const upc_mj* h, int b) { return h->m->body_parentid[b]; }
int upc_mj_dof_bodyid(const upc_mj* h, int v) { return h->m->dof_bodyid[v]; }

/* Data arrays allocated once by mj_makeData (stable addresses). */
double* upc_mj_qpos(upc_mj* h) { return h->d->qpos; }
double* upc_mj_qvel(upc_mj* h) { return h->d->qvel; }
double* upc_mj_qfrc_applied(upc_mj* h) { return h->d->qfrc_applied; }
const double* upc_mj_qfrc_bias(const upc_mj* h) { return h->d->qfrc_bias; }
const double* upc_mj_geom_xpos(const upc_mj* h) { return h->d->geom_xpos; }
const double* upc_mj_site_xpos(const upc_mj* h) { return h->d->site_xpos; }
const double* upc_mj_xmat(const upc_mj* h) { return h->d->xmat; }
const double* upc_mj_subtree_com(const upc_mj* h) { return h->d->subtree_com; }
double upc_mj_time(const upc_mj* h) { return h->d->time; }
void upc_mj_set_time(upc_mj* h, double t) { h->d->time = t; }
int upc_mj_solver_niter(const upc_mj* h) { return h->d->solver_niter[0]; }

/* Whether the last step raised one of the warnings on which MuJoCo resets its data. */
int upc_mj_diverged(const upc_mj* h) {
  const mjWarningStat* w = h->d->warning;
  return w[mjWARN_BADQACC].number > 0 || w[mjWARN_BADQVEL].number > 0 ||
         w[mjWARN_BADQPOS].number > 0;
}

/* The stages. */
void upc_mj_step(upc_mj* h) { mj_step(h->m, h->d); }
void upc_mj_forward(upc_mj* h) { mj_forward(h->m, h->d); }
/* Geometry and velocities of the current q, v (what a step leaves out of date). */
void upc_mj_positions_velocities(upc_mj* h) {
  mj_kinematics(h->m, h->d);
  mj_comPos(h->m, h->d);
  mj_comVel(h->m, h->d);
}

/* Contacts and constraint forces of the last constraint solve (arena memory: read per step). */
int upc_mj_ncon(const upc_mj* h) { return h->d->ncon; }
void upc_mj_contact(const upc_mj* h, int i, int geom[2], double frame[9]) {
  const mjContact* c = &h->d->contact[i];
  geom[0] = c->geom[0];
  geom[1] = c->geom[1];
  memcpy(frame, c->frame, 9 * sizeof(double));
}
void upc_mj_contact_force(const upc_mj* h, int i, double f[6]) {
  mj_contactForce(h->m, h->d, i, f);
}
int upc_mj_ne(const upc_mj* h) { return h->d->ne; }
int upc_mj_efc_id(const upc_mj* h, int r) { return h->d->efc_id[r]; }
double upc_mj_efc_force(const upc_mj* h, int r) { return h->d->efc_force[r]; }
/* Spatial velocity [angular; linear] of a geom, in the world frame. */
void upc_mj_geom_velocity(const upc_mj* h, int g, double out[6]) {
  mj_objectVelocity(h->m, h->d, mjOBJ_GEOM, g, out, 0);
}
