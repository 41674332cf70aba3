/* Runs a fastslam log (docs/log-format.md) through the C API, compiled as C99, and prints every
 * scan's estimate, associations and, at the end, the map and the counters with %a (exact hex
 * floats). c_api_webmap_reference.cc prints the same through engine::Filter; the CTest
 * c_api_webmap compares the two byte for byte.
 *
 * usage: c_api_webmap_driver LOG ALGORITHM ASSOCIATION PARTICLES SEED THREADS [RELOAD_EVERY STATE]
 * With RELOAD_EVERY = K > 0 the filter is saved and replaced by its restored copy after every
 * K-th scan, alternately through a memory buffer and through the file STATE: the output must
 * not change.
 *
 * Reads only what the filter needs from the log: the header and the control and scan records
 * (the reader is strict about those, lenient about the rest). */
#include <errno.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bindings/c/fastslam.h"

static void die(const char* what, const char* detail) {
  fprintf(stderr, "c_api_webmap_driver: %s%s%s\n", what, detail[0] != '\0' ? ": " : "", detail);
  exit(1);
}

static void check(fastslam_status status, const char* call, const fastslam_filter* filter) {
  if (status != FASTSLAM_OK) {
    fprintf(stderr, "c_api_webmap_driver: %s: %s: %s\n", call, fastslam_status_string(status),
            fastslam_last_error(filter));
    exit(1);
  }
}

/* One line of the file, without its newline, in a buffer that grows; NULL at the end. */
static char* read_line(FILE* in, char** buffer, size_t* capacity) {
  size_t length = 0;
  int c;
  while ((c = getc(in)) != EOF && c != '\n') {
    if (length + 1 >= *capacity) {
      *capacity = *capacity == 0 ? 256 : 2 * *capacity;
      *buffer = (char*)realloc(*buffer, *capacity);
      if (*buffer == NULL) die("out of memory", "");
    }
    (*buffer)[length++] = (char)c;
  }
  if (c == EOF && length == 0) return NULL;
  if (*buffer == NULL) {
    *capacity = 256;
    *buffer = (char*)malloc(*capacity);
    if (*buffer == NULL) die("out of memory", "");
  }
  (*buffer)[length] = '\0';
  return *buffer;
}

/* The next space- or tab-separated field of *cursor, NUL-terminated in place; NULL at the end. */
static char* next_field(char** cursor) {
  char* p = *cursor;
  char* start;
  while (*p == ' ' || *p == '\t' || *p == '\r') ++p;
  if (*p == '\0') return NULL;
  start = p;
  while (*p != '\0' && *p != ' ' && *p != '\t' && *p != '\r') ++p;
  if (*p != '\0') *p++ = '\0';
  *cursor = p;
  return start;
}

static double number(char** cursor) {
  char* field = next_field(cursor);
  char* end;
  double value;
  if (field == NULL) die("a field is missing", "");
  errno = 0;
  value = strtod(field, &end);
  if (*end != '\0' || errno == ERANGE) die("not a number", field);
  return value;
}

/* Appends to the JSON text, which has room for any header. */
static void append(char* json, size_t capacity, const char* text) {
  if (strlen(json) + strlen(text) >= capacity) die("configuration too long", "");
  strcat(json, text);
}

static void append_number(char* json, size_t capacity, const char* key, double value) {
  char text[128];
  /* %.17e reads back to the same bits, -0 included (JSON "-0" would be the integer 0). */
  sprintf(text, "\"%s\":%.17e", key, value);
  append(json, capacity, text);
}

/* What the filter needs of a log's header. */
struct header {
  char kind[64];
  int parameters; /* 1 (bailey-car: wheelbase) or 4 (ackermann: a, b, l, h) or 0 */
  double parameter[4];
  double noise[2];
  double sensor[7]; /* sigma range, sigma bearing, max range, field of view, offset x, y, yaw */
  double start[3];
};

/* Appends the header's keys to the configuration and closes it. */
static void configuration(char* json, size_t capacity, const struct header* h) {
  static const char* const geometry[4] = {"a", "b", "l", "h"};
  static const char* const sensor[4] = {"sigma_range", "sigma_bearing", "max_range",
                                        "field_of_view"};
  static const char* const offset[3] = {"x", "y", "yaw"};
  char text[128];
  int k;
  sprintf(text, ",\"motion\":{\"kind\":\"%s\",", h->kind);
  append(json, capacity, text);
  if (h->parameters == 1) {
    append_number(json, capacity, "wheelbase", h->parameter[0]);
    append(json, capacity, ",");
  } else if (h->parameters == 4) {
    append(json, capacity, "\"geometry\":{");
    for (k = 0; k < 4; ++k) {
      append_number(json, capacity, geometry[k], h->parameter[k]);
      append(json, capacity, k < 3 ? "," : "},");
    }
  }
  sprintf(text, "\"sigma_control\":[%.17e,%.17e]},\"sensor\":{", h->noise[0], h->noise[1]);
  append(json, capacity, text);
  for (k = 0; k < 4; ++k) {
    append_number(json, capacity, sensor[k], h->sensor[k]);
    append(json, capacity, ",");
  }
  append(json, capacity, "\"offset\":{");
  for (k = 0; k < 3; ++k) {
    append_number(json, capacity, offset[k], h->sensor[4 + k]);
    append(json, capacity, k < 2 ? "," : "}},");
  }
  sprintf(text, "\"initial_pose\":[%.17e,%.17e,%.17e]}", h->start[0], h->start[1], h->start[2]);
  append(json, capacity, text);
}

static void print_estimate(fastslam_filter* filter, unsigned long scan,
                           fastslam_association** associations, size_t* capacity) {
  fastslam_estimate e;
  size_t count = 0;
  size_t i;
  check(fastslam_get_estimate(filter, &e), "fastslam_get_estimate", filter);
  printf("scan %lu t=%a mean=%a %a %a cov=", scan, e.time, e.mean_pose[0], e.mean_pose[1],
         e.mean_pose[2]);
  for (i = 0; i < 9; ++i) printf("%a%s", e.pose_covariance[i], i < 8 ? "," : "");
  printf(" best=%a %a %a particle=%" PRIu32 " ess=%a landmarks=%lu observations=%lu\n",
         e.best_pose[0], e.best_pose[1], e.best_pose[2], e.best_particle, e.effective_sample_size,
         (unsigned long)e.landmark_count, (unsigned long)e.observation_count);
  check(fastslam_get_associations(filter, NULL, 0, &count), "fastslam_get_associations", filter);
  if (count != e.observation_count) die("the association count differs from the estimate's", "");
  if (count > *capacity) {
    *capacity = count;
    *associations = (fastslam_association*)realloc(*associations, count * sizeof **associations);
    if (*associations == NULL) die("out of memory", "");
  }
  if (count > 0) {
    check(fastslam_get_associations(filter, *associations, *capacity, &count),
          "fastslam_get_associations", filter);
  }
  for (i = 0; i < count; ++i) {
    const fastslam_association* a = &(*associations)[i];
    printf("  z%" PRIu32 " outcome=%" PRId32 " landmark=%" PRIu64 " d2=%a\n", a->observation,
           a->outcome, a->landmark_id, a->mahalanobis2);
  }
}

static void print_map_and_counters(fastslam_filter* filter, int reloaded) {
  fastslam_landmark* map;
  fastslam_statistics s;
  size_t count = 0;
  size_t i;
  check(fastslam_get_map(filter, NULL, 0, &count), "fastslam_get_map", filter);
  map = (fastslam_landmark*)malloc((count > 0 ? count : 1) * sizeof *map);
  if (map == NULL) die("out of memory", "");
  check(fastslam_get_map(filter, map, count, &count), "fastslam_get_map", filter);
  printf("map %lu\n", (unsigned long)count);
  for (i = 0; i < count; ++i) {
    printf("  %" PRIu32 " id=%" PRIu64 " %a %a cov=%a,%a,%a log_odds=%a last_seen=%" PRId64 "\n",
           map[i].slot, map[i].id, map[i].x, map[i].y, map[i].sxx, map[i].sxy, map[i].syy,
           map[i].log_odds, map[i].last_seen);
  }
  free(map);
  check(fastslam_get_statistics(filter, &s), "fastslam_get_statistics", filter);
  printf("controls=%" PRIu64 " scans=%" PRIu64 " observations=%" PRIu64 " resamples=%" PRIu64
         " weight_resets=%" PRIu64 "\n",
         s.controls, s.scans, s.observations, s.resamples, s.weight_resets);
  /* Counted since construction or load: comparable only without reloads. */
  if (!reloaded) {
    printf("created=%" PRIu64 " removed=%" PRIu64 " log_evidence=%a\n", s.landmarks_created,
           s.landmarks_removed, s.log_evidence);
  }
}

/* Saves the filter and replaces it by its restored copy: through a buffer the library
 * allocates, a buffer of ours (after a size query), or the file `state`, in turn. */
static fastslam_filter* reload(fastslam_filter* filter, unsigned long round, const char* state) {
  fastslam_filter* restored = NULL;
  void* data = NULL;
  size_t size = 0;
  switch (round % 3) {
    case 0:
      check(fastslam_save_alloc(filter, &data, &size), "fastslam_save_alloc", filter);
      check(fastslam_load_buffer(data, size, &restored), "fastslam_load_buffer", NULL);
      fastslam_free(data);
      break;
    case 1:
      check(fastslam_save_buffer(filter, NULL, 0, &size), "fastslam_save_buffer", filter);
      data = malloc(size);
      if (data == NULL) die("out of memory", "");
      check(fastslam_save_buffer(filter, data, size, &size), "fastslam_save_buffer", filter);
      check(fastslam_load_buffer(data, size, &restored), "fastslam_load_buffer", NULL);
      free(data);
      break;
    default:
      check(fastslam_save_file(filter, state), "fastslam_save_file", filter);
      check(fastslam_load_file(state, &restored), "fastslam_load_file", NULL);
      break;
  }
  fastslam_destroy(filter);
  return restored;
}

int main(int argc, char** argv) {
  FILE* in;
  char* line_buffer = NULL;
  size_t line_capacity = 0;
  char* line;
  char json[4096] = "{";
  char text[512];
  fastslam_filter* filter = NULL;
  fastslam_observation* scan = NULL;
  size_t scan_capacity = 0;
  fastslam_association* associations = NULL;
  size_t association_capacity = 0;
  unsigned long scans = 0;
  unsigned long reload_every = 0;
  const char* state = NULL;
  struct header header;
  int in_header = 1;
  int first = 1;
  int k;

  if (argc != 7 && argc != 9) {
    fprintf(stderr,
            "usage: %s LOG ALGORITHM ASSOCIATION PARTICLES SEED THREADS [RELOAD_EVERY STATE]\n",
            argv[0]);
    return 2;
  }
  if (argc == 9) {
    reload_every = strtoul(argv[7], NULL, 10);
    state = argv[8];
  }
  memset(&header, 0, sizeof header);
  in = fopen(argv[1], "r");
  if (in == NULL) die("cannot open the log", argv[1]);
  if (strlen(argv[2]) + strlen(argv[3]) + strlen(argv[4]) + strlen(argv[5]) + strlen(argv[6]) >
      300) {
    die("arguments too long", "");
  }
  sprintf(text,
          "\"algorithm\":\"%s\",\"association\":\"%s\",\"particles\":%s,\"seed\":%s,"
          "\"threads\":%s",
          argv[2], argv[3], argv[4], argv[5], argv[6]);
  append(json, sizeof json, text);

  while ((line = read_line(in, &line_buffer, &line_capacity)) != NULL) {
    char* cursor = line;
    char* record = next_field(&cursor);
    if (record == NULL || record[0] == '#') continue;
    if (first) {
      if (strcmp(record, "fastslam-log") != 0) die("not a fastslam log", argv[1]);
      first = 0;
      continue;
    }
    if (in_header) {
      if (strcmp(record, "motion") == 0) {
        const char* kind = next_field(&cursor);
        if (kind == NULL || strlen(kind) >= sizeof header.kind) die("bad motion line", "");
        strcpy(header.kind, kind);
        if (strcmp(kind, "bailey-car") == 0) {
          header.parameters = 1;
        } else if (strcmp(kind, "ackermann") == 0 || strcmp(kind, "victoria-park") == 0) {
          header.parameters = 4;
        }
        for (k = 0; k < header.parameters; ++k) header.parameter[k] = number(&cursor);
      } else if (strcmp(record, "control_noise") == 0) {
        for (k = 0; k < 2; ++k) header.noise[k] = number(&cursor);
      } else if (strcmp(record, "sensor") == 0) {
        for (k = 0; k < 7; ++k) header.sensor[k] = number(&cursor);
      } else if (strcmp(record, "start") == 0) {
        number(&cursor); /* the start time: the first timed record sets the clock */
        for (k = 0; k < 3; ++k) header.start[k] = number(&cursor);
      } else if (strcmp(record, "end_header") == 0) {
        in_header = 0;
        configuration(json, sizeof json, &header);
        check(fastslam_create(json, &filter), "fastslam_create", NULL);
      } else {
        die("unknown header line", record);
      }
      continue;
    }
    if (strcmp(record, "control") == 0) {
      const double t = number(&cursor);
      const double dt = number(&cursor);
      const double u0 = number(&cursor);
      const double u1 = number(&cursor);
      check(fastslam_predict_timed(filter, u0, u1, dt, t), "fastslam_predict_timed", filter);
    } else if (strcmp(record, "scan") == 0) {
      const double t = number(&cursor);
      const double n = number(&cursor);
      size_t count;
      size_t i;
      if (!(n >= 0 && n < 1e7) || n != (double)(size_t)n) die("bad observation count", "");
      count = (size_t)n;
      if (count > scan_capacity) {
        scan_capacity = count;
        scan = (fastslam_observation*)realloc(scan, count * sizeof *scan);
        if (scan == NULL) die("out of memory", "");
      }
      for (i = 0; i < count; ++i) {
        char* id;
        scan[i].range = number(&cursor);
        scan[i].bearing = number(&cursor);
        id = next_field(&cursor);
        if (id == NULL) die("an id is missing", "");
        scan[i].id = strcmp(id, "-") == 0 ? -1 : strtoll(id, NULL, 10);
      }
      check(fastslam_observe_timed(filter, scan, count, t), "fastslam_observe_timed", filter);
      print_estimate(filter, scans, &associations, &association_capacity);
      ++scans;
      if (reload_every > 0 && scans % reload_every == 0) {
        filter = reload(filter, scans / reload_every, state);
      }
    }
  }
  if (filter == NULL) die("the log has no end_header", "");
  print_map_and_counters(filter, reload_every > 0);
  fastslam_destroy(filter);
  fclose(in);
  free(line_buffer);
  free(scan);
  free(associations);
  return 0;
}
