/* Uses the installed C API (<fastslam/fastslam.h>, libfastslam) from C99: the same drive past
 * one landmark as main.cc, and an error's message. */
#include <fastslam/fastslam.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

int main(void) {
  fastslam_filter* filter = NULL;
  fastslam_estimate e;
  fastslam_landmark map[2];
  size_t count = 0;
  int t;
  if (fastslam_create("{\"unknown\": 1}", &filter) != FASTSLAM_INVALID_ARGUMENT ||
      strstr(fastslam_last_error(NULL), "unknown key") == NULL) {
    puts("c_consumer: a bad configuration was not refused");
    return 1;
  }
  if (fastslam_create("{\"algorithm\": \"fastslam2\", \"particles\": 20, \"threads\": 2}",
                      &filter) != FASTSLAM_OK) {
    printf("c_consumer: %s\n", fastslam_last_error(NULL));
    return 1;
  }
  for (t = 1; t <= 8; ++t) {
    const double dx = 10.0 - t;
    const double dy = 5.0;
    fastslam_observation z;
    z.range = sqrt(dx * dx + dy * dy);
    z.bearing = atan2(dy, dx);
    z.id = 0;
    if (fastslam_predict(filter, 1.0, 0.0, 1.0) != FASTSLAM_OK ||
        fastslam_observe(filter, &z, 1) != FASTSLAM_OK) {
      printf("c_consumer: %s\n", fastslam_last_error(filter));
      return 1;
    }
  }
  if (fastslam_get_estimate(filter, &e) != FASTSLAM_OK ||
      fastslam_get_map(filter, map, 2, &count) != FASTSLAM_OK || count != 1 ||
      hypot(map[0].x - 10.0, map[0].y - 5.0) > 3.0) {
    puts("c_consumer: the filter did not map the landmark");
    return 1;
  }
  printf("c_consumer: ok (library %s, landmark at %.2f, %.2f)\n", fastslam_version(), map[0].x,
         map[0].y);
  fastslam_destroy(filter);
  return 0;
}
