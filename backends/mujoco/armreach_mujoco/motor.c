/* PyBullet's position motor's reference, written by MuJoCo's control callback.
 *
 * armreach_mujoco.servo's motor rows need, in every physics step, the position term
 * offset - k q added to their reference acceleration after MuJoCo computes it (mj_step1)
 * and before it solves the constraints (mj_step2). Installed as mjcb_control, this does
 * that inside mj_step, so a control step is one mj_step(model, data, substeps) call with
 * no Python between physics steps. The arithmetic is that of the Python loop it replaces
 * (k = gain / dt^2, then k target - k q, or k target + (-k) q, which is the same number: a
 * negated product is exact; then added to the reference), compiled without contracting it
 * into fused multiply-adds, so the two give the same bits. It reads the motors' gains and
 * targets from Python's arrays as they are when MuJoCo calls it.
 *
 * A motor is a slot owned by Python (armreach_mujoco.cmotor): it acts only on its own
 * mjData, and only while Python marks it active around its mj_step call; every other
 * mj_forward or mj_step in the process passes through untouched.
 */
#include <stdint.h>

#include <mujoco/mjdata.h>
#include <mujoco/mjmodel.h>

typedef struct {
  const mjData* data;       /* the mjData this motor drives */
  int64_t active;           /* nonzero while its mj_step call runs */
  int64_t n;                /* motors: the model's last n friction rows, in order */
  const int64_t* qadr;      /* n addresses in qpos */
  const double* gains;      /* n: positionGain of each motor */
  const double* targets;    /* n: each motor's target */
  int64_t calls;            /* physics steps it has written, for Python's check */
} armreach_motor;

#define ARMREACH_SLOTS 4096
static armreach_motor* volatile slots[ARMREACH_SLOTS];
static volatile int used;  /* slots[used:] are all empty */

int armreach_motor_register(armreach_motor* slot) {
  for (int i = 0; i < ARMREACH_SLOTS; i++) {
    if (!slots[i]) {
      slots[i] = slot;
      if (i >= used) used = i + 1;
      return i;
    }
  }
  return -1;
}

void armreach_motor_unregister(int i) {
  if (i >= 0 && i < ARMREACH_SLOTS) slots[i] = 0;
}

int armreach_motor_abi(void) { return (int)sizeof(armreach_motor); }

void armreach_motor_control(const mjModel* m, mjData* d) {
  int end = used;
  for (int s = 0; s < end; s++) {
    armreach_motor* slot = slots[s];
    if (!slot || slot->data != d || !slot->active) continue;
    int64_t n = slot->n;
    mjtNum* aref = d->efc_aref + (d->ne + d->nf - n);
    const mjtNum* qpos = d->qpos;
    const int64_t* qadr = slot->qadr;
    const double* gains = slot->gains;
    const double* targets = slot->targets;
    double dt2 = m->opt.timestep * m->opt.timestep;
    for (int64_t i = 0; i < n; i++) {
      double k = gains[i] / dt2;  /* k = gain / dt^2, offset = k target: as servo.Motors computes them */
      aref[i] += k * targets[i] - qpos[qadr[i]] * k;
    }
    slot->calls++;
    return;
  }
}
