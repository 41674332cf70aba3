/* The C API of fastslam (C99; usable from C++): a FastSLAM 1.0 / 2.0 filter behind an opaque
 * handle, configured by a JSON string (the keys of engine::FilterConfig: docs/c-api.md), fed
 * controls and scans, read back as an estimate, a map and the last scan's associations, saved
 * and restored through a file or a memory buffer. Installed as <fastslam/fastslam.h>; the
 * library is libfastslam.so and exports only the fastslam_* functions below.
 *
 * Errors: every function that can fail returns a fastslam_status; on failure it changes
 * nothing (output pointers of a failed create or load are set to NULL) and
 * fastslam_last_error() gives the message, the same text the C++ engine's exception carries.
 * No C++ exception and no abort crosses this boundary, whatever the input: NULL pointers, NaN,
 * counts that are negative numbers converted to size_t, corrupt saved states.
 *
 * Ownership: the caller owns every buffer it passes; the library only reads the inputs during
 * the call and writes the outputs before it returns. A handle owns its filter (particles,
 * maps, worker threads) until fastslam_destroy.
 *
 * Thread safety: a handle is thread-compatible: calls on one handle must not overlap (use it
 * from one thread at a time, or serialise the calls yourself); distinct handles are
 * independent and may be used from different threads concurrently. fastslam_version,
 * fastslam_status_string and fastslam_last_error(NULL) may be called from any thread.
 *
 * Costs, for M particles, N landmarks in a map, Z observations in a scan: predict O(1)
 * amortised (the work runs at the next observe or estimate); observe O(M Z log N) (plus the
 * candidate search for unknown association); estimate, map and associations O(M + N) for the
 * first of them after a change of the filter, O(1) (estimate) or O(N) (copies) after that;
 * save O(M N) worst case, usually far less (the particles share map nodes).
 */
#ifndef FASTSLAM_FASTSLAM_H
#define FASTSLAM_FASTSLAM_H

#include <stddef.h>
#include <stdint.h>

#if defined(_WIN32)
#if defined(FASTSLAM_C_BUILD)
#define FASTSLAM_API __declspec(dllexport)
#else
#define FASTSLAM_API __declspec(dllimport)
#endif
#elif defined(__GNUC__)
#define FASTSLAM_API __attribute__((visibility("default")))
#else
#define FASTSLAM_API
#endif

#ifdef __cplusplus
extern "C" {
#endif

/* The version of this header; fastslam_version() gives the library's. */
#define FASTSLAM_VERSION "0.1.0"
#define FASTSLAM_VERSION_MAJOR 0
#define FASTSLAM_VERSION_MINOR 1
#define FASTSLAM_VERSION_PATCH 0

/* The largest element count any call accepts (observations, map and association buffers):
 * 2^31 - 1. A negative 32- or 64-bit count that reached size_t (as a foreign-function
 * interface may pass it) is larger, and is refused with FASTSLAM_INVALID_ARGUMENT instead of
 * being read as a huge buffer. Byte sizes (saved states) are limited to PTRDIFF_MAX. */
#define FASTSLAM_MAX_COUNT ((size_t)2147483647)

typedef enum fastslam_status {
  FASTSLAM_OK = 0,
  FASTSLAM_INVALID_ARGUMENT = 1, /* a NULL pointer, NaN, a bad count, time going backwards, a
                                    configuration the parser or the filter refuses */
  FASTSLAM_CORRUPT_STATE = 2,    /* load: the data is not a saved filter state */
  FASTSLAM_IO_ERROR = 3,         /* a file could not be opened, read or written */
  FASTSLAM_OUT_OF_MEMORY = 4,
  FASTSLAM_BUFFER_TOO_SMALL = 5, /* nothing written; the size needed is in the count output */
  FASTSLAM_INTERNAL = 6          /* a bug: please report the message */
} fastslam_status;

/* A filter. Opaque: create, use and destroy it through the functions below. */
typedef struct fastslam_filter fastslam_filter;

/* One detection of a scan. */
typedef struct fastslam_observation {
  double range;   /* m, > 0 */
  double bearing; /* rad, counter-clockwise from the sensor's heading */
  int64_t id;     /* the landmark's identity, >= 0, with "association": "known"; else ignored */
} fastslam_observation;

/* The filter's summary after the latest data (poses are x, y, theta, then v and omega for the
 * motion kind "none", v and kappa for "none-curvature", else 0). */
typedef struct fastslam_estimate {
  double time; /* the latest data's time: the last time given (timed calls), advanced by the dt
                  of every untimed predict since; 0 until a time is given */
  double mean_pose[5];       /* weighted mean over the particles (heading by circular mean) */
  double pose_covariance[9]; /* of (x, y, theta) about mean_pose, row-major */
  double best_pose[5];       /* the pose of the particle of highest weight */
  uint32_t best_particle;
  double effective_sample_size; /* 1 / sum of squared normalised weights, in [1, particles] */
  size_t landmark_count;        /* the best particle's confirmed landmarks (fastslam_get_map) */
  size_t observation_count;     /* observations of the last scan (fastslam_get_associations) */
} fastslam_estimate;

/* A landmark of the best particle's map, in that particle's frame. */
typedef struct fastslam_landmark {
  uint64_t id;          /* known association: the observations' id; else assigned at creation */
  double x, y;          /* mean, m */
  double sxx, sxy, syy; /* covariance, m^2 */
  double log_odds;      /* existence (unknown association) */
  int64_t last_seen;    /* the scan that last updated it */
  uint32_t slot;        /* its slot in the particle's map */
} fastslam_landmark;

typedef enum fastslam_outcome {
  FASTSLAM_ASSOCIATED = 0, /* updated an existing landmark */
  FASTSLAM_NEW = 1,        /* started a landmark */
  FASTSLAM_DISCARDED = 2   /* left out of the map (never, in FastSLAM) */
} fastslam_outcome;

/* What became of one observation of the last scan, in the particle of highest weight. */
typedef struct fastslam_association {
  uint32_t observation; /* index in the scan */
  int32_t outcome;      /* a fastslam_outcome */
  uint64_t landmark_id; /* the landmark it updated or started (fastslam_landmark.id) */
  double mahalanobis2;  /* squared Mahalanobis distance to it; +inf when none applies */
} fastslam_association;

/* Counters since creation (or the save that was loaded), and time spent. */
typedef struct fastslam_statistics {
  uint64_t controls;     /* predict calls */
  uint64_t scans;        /* observe calls */
  uint64_t observations; /* detections in all scans */
  uint64_t resamples;
  uint64_t weight_resets; /* scans after which every weight was zero */
  uint64_t landmarks_created;
  uint64_t landmarks_removed;
  double log_evidence; /* ln p(z | u) estimated by the filter */
  double predict_seconds, associate_seconds, update_seconds, resample_seconds; /* thread-s */
  double observe_wall_seconds;
  int64_t live_nodes, live_bytes; /* the map trees of all particles together */
} fastslam_statistics;

/* "0.1.0": the library's version. Static storage. */
FASTSLAM_API const char* fastslam_version(void);

/* "FASTSLAM_OK", "FASTSLAM_INVALID_ARGUMENT", ...; "unknown status" otherwise. Static. */
FASTSLAM_API const char* fastslam_status_string(fastslam_status status);

/* The message of the latest failure. With a handle: of the latest call on it, "" when that
 * call succeeded. With NULL: of the latest failed call on the calling thread, any handle or
 * none (how a failed fastslam_create or fastslam_load_* explains itself); "" if none yet.
 * The text stays valid until the next call on that handle (or, for NULL, on this thread). */
FASTSLAM_API const char* fastslam_last_error(const fastslam_filter* filter);

/* Creates a filter from a NUL-terminated JSON object ("{}": every default). On success *out
 * owns a new filter (fastslam_destroy releases it); on failure *out is NULL and
 * fastslam_last_error(NULL) says why (invalid JSON with line and column, the key path of an
 * unknown key, a wrong type or value). Algorithm "ekf" is refused (it is not a particle
 * filter). Starts the filter's worker threads ("threads": 0 means one per core). */
FASTSLAM_API fastslam_status fastslam_create(const char* json_config, fastslam_filter** out);

/* Releases the filter and everything it owns; NULL is ignored. Waits for its background work. */
FASTSLAM_API void fastslam_destroy(fastslam_filter* filter);

/* The filter's configuration as JSON with every key (fastslam_create of it makes the same
 * filter), NUL-terminated. Copies strlen + 1 bytes into buf when capacity allows, else returns
 * FASTSLAM_BUFFER_TOO_SMALL; either way *size is strlen + 1. buf NULL: only the size query. */
FASTSLAM_API fastslam_status fastslam_get_config(fastslam_filter* filter, char* buf,
                                                 size_t capacity, size_t* size);

/* Queues one control (u0, u1) held for dt >= 0 seconds; the meaning of u0, u1 is the motion
 * model's (bailey-car: speed m/s and steering rad). The timed form also sets the filter's clock
 * to `time`, which must not be before the latest time given. NaN or infinite values, dt < 0
 * and time going backwards are refused (FASTSLAM_INVALID_ARGUMENT). */
FASTSLAM_API fastslam_status fastslam_predict(fastslam_filter* filter, double u0, double u1,
                                              double dt);
FASTSLAM_API fastslam_status fastslam_predict_timed(fastslam_filter* filter, double u0, double u1,
                                                    double dt, double time);

/* Runs the queued controls and this scan of `count` observations through every particle, then
 * resamples as configured. `observations` may be NULL when count is 0 (a scan that saw
 * nothing). Refused: a range <= 0, a NaN, a missing or repeated id with known association,
 * count > FASTSLAM_MAX_COUNT, time going backwards (timed form). */
FASTSLAM_API fastslam_status fastslam_observe(fastslam_filter* filter,
                                              const fastslam_observation* observations,
                                              size_t count);
FASTSLAM_API fastslam_status fastslam_observe_timed(fastslam_filter* filter,
                                                    const fastslam_observation* observations,
                                                    size_t count, double time);

/* Fills *out with the current estimate (runs any queued controls first). */
FASTSLAM_API fastslam_status fastslam_get_estimate(fastslam_filter* filter, fastslam_estimate* out);

/* Copies the best particle's map, in slot order. *count is set to the number of landmarks.
 * buf NULL: only that size query. Otherwise capacity must be at least *count (else
 * FASTSLAM_BUFFER_TOO_SMALL, nothing copied). Reads the same snapshot as fastslam_get_estimate:
 * the calls between two changes of the filter agree. */
FASTSLAM_API fastslam_status fastslam_get_map(fastslam_filter* filter, fastslam_landmark* buf,
                                              size_t capacity, size_t* count);

/* Copies the last scan's associations, one per observation in scan order; as fastslam_get_map for
 * the buffer. Empty before the first scan. */
FASTSLAM_API fastslam_status fastslam_get_associations(fastslam_filter* filter,
                                                       fastslam_association* buf, size_t capacity,
                                                       size_t* count);

/* Counters and timings. O(1). */
FASTSLAM_API fastslam_status fastslam_get_statistics(fastslam_filter* filter,
                                                     fastslam_statistics* out);

/* Saves the whole state (configuration, particles, maps, queued controls, clock) to a file,
 * which is replaced. A filter loaded from it continues bit for bit as this one would. On
 * failure (FASTSLAM_IO_ERROR) the file may be partly written. */
FASTSLAM_API fastslam_status fastslam_save_file(fastslam_filter* filter, const char* path);

/* Creates a filter from a file fastslam_save_file wrote; *out as fastslam_create.
 * FASTSLAM_IO_ERROR when the file cannot be read, FASTSLAM_CORRUPT_STATE when it is not a
 * saved state (truncated, altered, another format, bytes after its end). */
FASTSLAM_API fastslam_status fastslam_load_file(const char* path, fastslam_filter** out);

/* Saves the state into the caller's buffer: *size is set to the bytes it takes; buf NULL is
 * the size query, else capacity must be at least *size (else FASTSLAM_BUFFER_TOO_SMALL,
 * nothing copied). A size query keeps the serialised bytes until the next call on the filter,
 * so the query and the copy right after it serialise once. */
FASTSLAM_API fastslam_status fastslam_save_buffer(fastslam_filter* filter, void* buf,
                                                  size_t capacity, size_t* size);

/* Saves the state into memory the library allocates: *data (release it with fastslam_free)
 * and *size. On failure *data is NULL and *size 0. */
FASTSLAM_API fastslam_status fastslam_save_alloc(fastslam_filter* filter, void** data,
                                                 size_t* size);

/* Releases memory from fastslam_save_alloc; NULL is ignored. */
FASTSLAM_API void fastslam_free(void* data);

/* Creates a filter from `size` bytes fastslam_save_buffer or fastslam_save_alloc wrote; *out
 * as fastslam_create; FASTSLAM_CORRUPT_STATE as fastslam_load_file. The bytes are only read
 * during the call. */
FASTSLAM_API fastslam_status fastslam_load_buffer(const void* data, size_t size,
                                                  fastslam_filter** out);

#ifdef __cplusplus
} /* extern "C" */
#endif

#endif /* FASTSLAM_FASTSLAM_H */
