/* Run the generated manipulator observer / fault estimator / tolerant controller on recorded
 * measurements and print, per sample, k, the control input u and the fault estimates fhat.
 *
 * Build (from the repository root, strict flags as for any caller):
 *   cc -std=c99 -O2 -Wall -Wextra -Werror -pedantic -Igenerated/manipulator
 *      generated/manipulator/fte_*.c examples/embedded/main.c -o fte_example -lm
 * Run:
 *   ./fte_example examples/embedded/measurements.txt
 *
 * The measurement file holds one sample per line, FTE_MANIPULATOR_NY numbers (theta_m, w_m,
 * theta_l) separated by blanks; lines starting with '#' are comments. It was recorded every
 * FTE_MANIPULATOR_TS seconds (see make_measurements.py). This main reads a file and prints;
 * the generated code itself does neither. */
#include <stdio.h>
#include <string.h>

#include "fte_manipulator.h"

static int read_sample(FILE *fp, fte_real *y) {
  char line[512];
  while (fgets(line, sizeof line, fp) != NULL) {
    double v[FTE_MANIPULATOR_NY];
    char *p = line;
    int i, used;
    if (line[0] == '#' || line[0] == '\n') continue;
    for (i = 0; i < FTE_MANIPULATOR_NY; ++i) {
      if (sscanf(p, "%lf%n", &v[i], &used) != 1) return -1;
      p += used;
      y[i] = (fte_real)v[i];
    }
    return 1;
  }
  return 0;
}

int main(int argc, char **argv) {
  const char *path = argc > 1 ? argv[1] : "measurements.txt";
  fte_manipulator_state st;
  fte_real y[FTE_MANIPULATOR_NY], u[FTE_MANIPULATOR_NU], xbarhat[FTE_MANIPULATOR_NXBAR];
  fte_real yc[FTE_MANIPULATOR_NY];
  FILE *fp = fopen(path, "r");
  int k = 0, rc, i;
  if (fp == NULL) {
    fprintf(stderr, "cannot open %s\n", path);
    return 2;
  }
  memset(u, 0, sizeof u);
  printf("# k u fhat_fa fhat_fs (Ts = %g s)\n", (double)FTE_MANIPULATOR_TS);
  while ((rc = read_sample(fp, y)) == 1) {
    /* start as fte simulate does, from the first measurement: z0 = xbar0 - H y0 */
    if (k == 0 && fte_manipulator_init_from_y(&st, y, NULL) != 0) {
      fprintf(stderr, "first measurement not finite: cannot start\n");
      fclose(fp);
      return 4;
    }
    if (fte_manipulator_step(&st, y, u, xbarhat, yc) != 0) {
      fprintf(stderr, "sample %d: measurement not finite, state kept, u held\n", k);
    }
    printf("%d", k);
    for (i = 0; i < FTE_MANIPULATOR_NU; ++i) printf(" %.17g", (double)u[i]);
    for (i = 0; i < FTE_MANIPULATOR_NF; ++i)
      printf(" %.17g", (double)xbarhat[FTE_MANIPULATOR_NX + FTE_MANIPULATOR_NF + i]);
    printf("\n");
    ++k;
  }
  fclose(fp);
  if (rc < 0) {
    fprintf(stderr, "%s: malformed line after sample %d\n", path, k);
    return 3;
  }
  return 0;
}
