/* The C side of the front-end overhead benchmark (front_end_overhead.py): reads a log's
 * controls and scans into memory, then times one pass through the C API, scan by scan:
 * fastslam_predict_timed for every control, fastslam_observe_timed for every scan, then
 * fastslam_get_estimate and fastslam_get_map (into a buffer that grows) and
 * fastslam_get_associations. Prints what front_end_cpp prints.
 * usage: front_end_c LOG PARTICLES SEED */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "bindings/c/fastslam.h"

typedef struct {
  int is_scan;
  double t, dt, u0, u1;
  size_t first, count;
} record;

static void check(fastslam_status s, const fastslam_filter* f) {
  if (s != FASTSLAM_OK) {
    fprintf(stderr, "front_end_c: %s\n", fastslam_last_error(f));
    exit(1);
  }
}

static void* grow(void* p, size_t* capacity, size_t needed, size_t size) {
  if (needed <= *capacity) return p;
  while (*capacity < needed) *capacity = *capacity == 0 ? 1024 : 2 * *capacity;
  p = realloc(p, *capacity * size);
  if (p == NULL) {
    fputs("front_end_c: out of memory\n", stderr);
    exit(1);
  }
  return p;
}

int main(int argc, char** argv) {
  static char line[1 << 16];
  record* records = NULL;
  size_t n_records = 0, cap_records = 0;
  fastslam_observation* obs = NULL;
  size_t n_obs = 0, cap_obs = 0;
  double start_pose[3] = {0, 0, 0};
  char config[4096];
  char motion[64];
  double wheelbase = 0, sigma0 = 0, sigma1 = 0, sensor[7] = {0, 0, 0, 0, 0, 0, 0};
  fastslam_filter* filter = NULL;
  fastslam_landmark* map = NULL;
  size_t cap_map = 0;
  fastslam_association assoc[4096];
  struct timespec t0, t1;
  size_t k, landmarks = 0;
  fastslam_estimate e;
  FILE* in;
  if (argc != 4) {
    fputs("usage: front_end_c LOG PARTICLES SEED\n", stderr);
    return 2;
  }
  in = fopen(argv[1], "r");
  if (in == NULL) {
    perror(argv[1]);
    return 1;
  }
  while (fgets(line, sizeof(line), in) != NULL) {
    char* p = line;
    if (strncmp(line, "motion ", 7) == 0) {
      sscanf(line, "motion %63s %lf", motion, &wheelbase);
    } else if (strncmp(line, "control_noise ", 14) == 0) {
      sscanf(line, "control_noise %lf %lf", &sigma0, &sigma1);
    } else if (strncmp(line, "sensor ", 7) == 0) {
      sscanf(line, "sensor %lf %lf %lf %lf %lf %lf %lf", &sensor[0], &sensor[1], &sensor[2],
             &sensor[3], &sensor[4], &sensor[5], &sensor[6]);
    } else if (strncmp(line, "start ", 6) == 0) {
      double t;
      sscanf(line, "start %lf %lf %lf %lf", &t, &start_pose[0], &start_pose[1], &start_pose[2]);
    } else if (strncmp(line, "control ", 8) == 0) {
      record r;
      memset(&r, 0, sizeof(r));
      sscanf(line, "control %lf %lf %lf %lf", &r.t, &r.dt, &r.u0, &r.u1);
      records = grow(records, &cap_records, n_records + 1, sizeof(record));
      records[n_records++] = r;
    } else if (strncmp(line, "scan ", 5) == 0) {
      record r;
      size_t j;
      char* end;
      memset(&r, 0, sizeof(r));
      r.is_scan = 1;
      p += 5;
      r.t = strtod(p, &end);
      p = end;
      r.count = strtoul(p, &end, 10);
      p = end;
      r.first = n_obs;
      obs = grow(obs, &cap_obs, n_obs + r.count, sizeof(fastslam_observation));
      for (j = 0; j < r.count; ++j) {
        fastslam_observation* z = &obs[n_obs++];
        z->range = strtod(p, &end);
        p = end;
        z->bearing = strtod(p, &end);
        p = end;
        while (*p == ' ') ++p;
        if (*p == '-') {
          z->id = -1;
          ++p;
        } else {
          z->id = strtoll(p, &end, 10);
          p = end;
        }
      }
      records = grow(records, &cap_records, n_records + 1, sizeof(record));
      records[n_records++] = r;
    }
  }
  fclose(in);
  snprintf(config, sizeof(config),
           "{\"particles\": %s, \"seed\": %s, \"threads\": 1, \"motion\": {\"kind\": \"%s\", "
           "\"wheelbase\": %.17g, \"sigma_control\": [%.17g, %.17g]}, \"sensor\": "
           "{\"sigma_range\": %.17g, \"sigma_bearing\": %.17g, \"max_range\": %.17g, "
           "\"field_of_view\": %.17g, \"offset\": {\"x\": %.17g, \"y\": %.17g, \"yaw\": %.17g}}, "
           "\"initial_pose\": [%.17g, %.17g, %.17g, 0, 0]}",
           argv[2], argv[3], motion, wheelbase, sigma0, sigma1, sensor[0], sensor[1], sensor[2],
           sensor[3], sensor[4], sensor[5], sensor[6], start_pose[0], start_pose[1],
           start_pose[2]);
  check(fastslam_create(config, &filter), NULL);
  clock_gettime(CLOCK_MONOTONIC, &t0);
  for (k = 0; k < n_records; ++k) {
    const record* r = &records[k];
    if (!r->is_scan) {
      check(fastslam_predict_timed(filter, r->u0, r->u1, r->dt, r->t), filter);
    } else {
      size_t count = 0;
      check(fastslam_observe_timed(filter, obs + r->first, r->count, r->t), filter);
      check(fastslam_get_estimate(filter, &e), filter);
      map = grow(map, &cap_map, e.landmark_count, sizeof(fastslam_landmark));
      check(fastslam_get_map(filter, map, cap_map, &count), filter);
      check(fastslam_get_associations(filter, assoc, 4096, &count), filter);
      landmarks += e.landmark_count;
    }
  }
  clock_gettime(CLOCK_MONOTONIC, &t1);
  check(fastslam_get_estimate(filter, &e), filter);
  printf("seconds %.9f\npose %a %a %a\nlandmarks %zu\n",
         (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec),
         e.mean_pose[0], e.mean_pose[1], e.mean_pose[2], landmarks);
  fastslam_destroy(filter);
  free(records);
  free(obs);
  free(map);
  return 0;
}
