/*
 * The site-validity rule (issue 10): declared once, in the site schema (its
 * sections' starts_alone, generated as SITE_STARTS_ALONE), applied by the
 * bridge's config_site_starts, and held by the library a second way (each
 * kind's starts_alone hook, lib/src/config.cpp check_kinds). Checked here:
 * the library's verdict on the bl_config the bridge maps agrees with the
 * schema's rule on a grid of counts, and the error lists every way out.
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <cmocka.h>

#include "beaconloc.h"
#include "config.h"
#include "site_keys.h"
#include "site_to_lib.h"

#define GRID 5 /* counts 0..4 of each kind */

/* n items on a circle about (5, 4): distinct, spanning the plane from 3 on. */
static void place(double *x, double *y, int i, int n) {
  const double a = 2.0 * M_PI * i / n + 0.3;
  *x = 5.0 + 3.0 * cos(a);
  *y = 4.0 + 2.0 * sin(a);
}

static void set_counts(struct bridge_config *cfg, const int n[6]) {
  config_defaults(cfg);
  cfg->beacon_count = n[0];
  cfg->bearing_beacon_count = n[1];
  cfg->range_beacon_count = n[2];
  cfg->sonar_ring.count = n[3];
  cfg->map.walls = n[4];
  cfg->team.robots = n[5];
  for (int i = 0; i < n[0]; i++) {
    place(&cfg->beacon[i].x_m, &cfg->beacon[i].y_m, i, n[0]);
    cfg->beacon[i].z_m = 2.5;
  }
  for (int i = 0; i < n[1]; i++)
    place(&cfg->bearing_beacon[i].x_m, &cfg->bearing_beacon[i].y_m, i, n[1]);
  for (int i = 0; i < n[2]; i++) {
    place(&cfg->range_beacon[i].x_m, &cfg->range_beacon[i].y_m, i, n[2]);
    cfg->range_beacon[i].z_m = 2.0;
  }
}

/* Every combination of 0..4 ultrasonic, bearing and range beacons, sonars,
 * walls and team robots: the library accepts the mapped bl_config exactly
 * when the schema's rule holds. The one difference is the ultrasonic count's
 * own range, which the rule leaves to the library: 1 or 2 beacons start
 * nothing ("0 or >= 3", [beacons] count's doc), refused as beacon_count. */
static void test_library_agrees_with_the_schema_rule(void **state) {
  (void)state;
  int n[6], seen[2] = {0, 0};
  struct bridge_config cfg;
  bl_config lc;
  for (int code = 0; code < GRID * GRID * GRID * GRID * GRID * GRID; code++) {
    for (int k = 0, c = code; k < 6; k++, c /= GRID)
      n[k] = c % GRID;
    set_counts(&cfg, n);
    const bool rule = config_site_starts(&cfg);
    site_to_lib(&cfg, &lc);
    const char *bad = NULL;
    const int rc = bl_config_check(&lc, &bad);
    seen[rule]++;
    if (n[0] == 1 || n[0] == 2) {
      if (!rule || rc != BL_ECONFIG || strcmp(bad, "beacon_count") != 0)
        fail_msg("counts %d %d %d %d %d %d: rule %d, library %d (%s)", n[0],
                 n[1], n[2], n[3], n[4], n[5], rule, rc, bad ? bad : "-");
    } else if (rule != (rc == BL_OK)) {
      fail_msg("counts %d %d %d %d %d %d: rule %d, library %d (%s)", n[0], n[1],
               n[2], n[3], n[4], n[5], rule, rc, bad ? bad : "-");
    }
  }
  /* both verdicts occur (the grid reaches each clause's boundary) */
  assert_true(seen[0] > 0 && seen[1] > 0);
}

/* The rule's clauses as the schema declares them, in its file order. */
static void test_rule_is_the_schemas(void **state) {
  (void)state;
  static const char *const want[] = {
      "0 beacons count 1",       "1 bearing_beacons count 3",
      "2 range_beacons count 3", "3 sonar_ring count 1",
      "3 map walls 1",           "4 team robots 1"};
  static const char *const got[] = {
#define ROW(clause, sec, k, member, lo) #clause " " #sec " " #k " " #lo,
      SITE_STARTS_ALONE(ROW)
#undef ROW
  };
  assert_int_equal(sizeof got / sizeof got[0], sizeof want / sizeof want[0]);
  for (size_t i = 0; i < sizeof want / sizeof want[0]; i++)
    assert_string_equal(got[i], want[i]);
  assert_int_equal(SITE_STARTS_ALONE_CLAUSES, 5);
}

/* Without a file (the built-in defaults): every clause, with its values. */
static void test_not_set_lists_every_way_out(void **state) {
  (void)state;
  struct bridge_config cfg;
  set_counts(&cfg, (const int[6]){0, 2, 1, 3, 0, 0});
  char err[CONFIG_ERR_LEN];
  assert_int_equal(config_check(&cfg, err, sizeof err), -1);
  assert_string_equal(
      err,
      "config: [beacons] count: not set: the site file must give the "
      "beacons: [beacons] count >= 1 (now 0), [bearing_beacons] count >= 3 "
      "(now 2), [range_beacons] count >= 3 (now 1), [sonar_ring] count >= "
      "1 and [map] walls >= 1 (now 3 and 0) or [team] robots >= 1 (now 0)");
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_library_agrees_with_the_schema_rule),
      cmocka_unit_test(test_rule_is_the_schemas),
      cmocka_unit_test(test_not_set_lists_every_way_out),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
