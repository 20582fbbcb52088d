/* Time mj_step in a C loop: median and minimum ns per step over repetitions.
 *
 * Built and run by scripts/mujoco_bench.py against the MuJoCo library that
 * the `mujoco` wheel ships (no separate MuJoCo install):
 *
 *   mujoco_step MODEL.xml NSTEP REPS qpos_1 .. qpos_nq qvel_1 .. qvel_nv
 *
 * Each repetition resets the data, sets (qpos, qvel), and times NSTEP calls
 * of mj_step with clock_gettime(CLOCK_MONOTONIC). Prints one line:
 *
 *   median_ns=<x> min_ns=<y> qpos_end=<q1,q2,...> warnings=<n>
 *
 * (the final qpos of the last repetition, to compare with the rollout's,
 * and the number of MuJoCo warnings raised). NSTEP = 0 runs no step: the
 * difference of callgrind's instruction totals at NSTEP and at 0, divided
 * by NSTEP, is the count per mj_step.
 */
#include <mujoco/mujoco.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

static int cmp(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

static double now_ns(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return 1e9 * (double)t.tv_sec + (double)t.tv_nsec;
}

int main(int argc, char **argv) {
  if (argc < 4) {
    fprintf(stderr, "usage: %s MODEL.xml NSTEP REPS qpos.. qvel..\n", argv[0]);
    return 2;
  }
  char err[1000] = "";
  mjModel *m = mj_loadXML(argv[1], NULL, err, sizeof err);
  if (!m) {
    fprintf(stderr, "mj_loadXML: %s\n", err);
    return 1;
  }
  long nstep = atol(argv[2]);
  int reps = atoi(argv[3]);
  if (nstep < 0 || reps <= 0 || argc != 4 + m->nq + m->nv) {
    fprintf(stderr, "need NSTEP >= 0, REPS > 0 and %d qpos + %d qvel values\n",
            (int)m->nq, (int)m->nv);
    return 2;
  }
  mjData *d = mj_makeData(m);
  double *t = malloc(sizeof(double) * (size_t)reps);
  int warnings = 0;
  for (int r = 0; r < reps; r++) {
    mj_resetData(m, d);
    for (int i = 0; i < m->nq; i++) d->qpos[i] = atof(argv[4 + i]);
    for (int i = 0; i < m->nv; i++) d->qvel[i] = atof(argv[4 + m->nq + i]);
    double t0 = now_ns();
    for (long k = 0; k < nstep; k++) mj_step(m, d);
    t[r] = nstep ? (now_ns() - t0) / (double)nstep : 0.0;
    for (int w = 0; w < mjNWARNING; w++) warnings += d->warning[w].number;
  }
  double lo = t[0];
  for (int r = 1; r < reps; r++) lo = t[r] < lo ? t[r] : lo;
  qsort(t, (size_t)reps, sizeof(double), cmp);
  double med = reps % 2 ? t[reps / 2] : 0.5 * (t[reps / 2 - 1] + t[reps / 2]);
  printf("median_ns=%.1f min_ns=%.1f qpos_end=", med, lo);
  for (int i = 0; i < m->nq; i++) printf(i ? ",%.17g" : "%.17g", d->qpos[i]);
  printf(" warnings=%d\n", warnings);
  free(t);
  mj_deleteData(d);
  mj_deleteModel(m);
  return 0;
}
