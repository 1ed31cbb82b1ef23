/*
 * cmocka: the sensor kinds against the DBC itself. The kind list (enum
 * frame_kind, sensor_kinds[]) is generated from the DBC at build time
 * (bridge/gen_frame_kinds.py) and each entry is written in its kind's file
 * (bridge/sensor_<kind>.c); this test reads the DBC's text on its own (not
 * through cantools or the generator) and fails where they disagree: every
 * frame the bridge receives (a signal names BRIDGE as its receiver) has
 * exactly one kind, numbered by its BridgeKind attribute, with the frame's
 * id, its name in lower case and the modulo of its Counter signal's range;
 * a frame the bridge sends has none. And the timebase rule, a field of each
 * kind's entry, is well formed and gives the clocks it gave as a chain of
 * cases (pulse receiver, else bearing sensor, else sonar ring on a site
 * without range beacons, else range receiver).
 */
#include <ctype.h>
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "estimator.h"
#include "frames.h"
#include "sensors.h"

#ifndef BRIDGE_DBC_PATH
#define BRIDGE_DBC_PATH "hw_sim/beaconloc_sim/data/beaconloc.dbc"
#endif

#define DBC_FRAMES_MAX 64

/* One BO_ of the DBC, as its text says it. */
struct dbc_frame {
  unsigned id;
  char name[64];
  bool to_bridge; /* a signal names BRIDGE among its receivers */
  unsigned
      counter_modulo; /* one past the Counter signal's largest value; 0: none */
  int bridge_kind;    /* BA_ "BridgeKind"; -1: none */
};

static struct dbc_frame frames[DBC_FRAMES_MAX];
static size_t n_frames;

static struct dbc_frame *frame_of_id(unsigned id) {
  for (size_t i = 0; i < n_frames; i++)
    if (frames[i].id == id)
      return &frames[i];
  return NULL;
}

/* Whether the receivers after a signal's unit string name BRIDGE. */
static bool names_bridge(const char *sg) {
  const char *p = strrchr(sg, '"');
  for (p = p ? p + 1 : sg; *p;) {
    while (*p == ' ' || *p == ',')
      p++;
    size_t n = strcspn(p, " ,\r\n");
    if (n == 6 && !strncmp(p, "BRIDGE", 6))
      return true;
    p += n ? n : 1;
  }
  return false;
}

static int read_dbc(void **state) {
  (void)state;
  FILE *f = fopen(BRIDGE_DBC_PATH, "r");
  if (!f)
    return -1;
  char *line = NULL;
  size_t cap = 0;
  struct dbc_frame *cur = NULL;
  while (getline(&line, &cap, f) >= 0) {
    unsigned id, kind;
    char name[64];
    if (sscanf(line, "BO_ %u %63[A-Za-z0-9_]:", &id, name) == 2) {
      assert_true(n_frames < DBC_FRAMES_MAX);
      cur = &frames[n_frames++];
      *cur = (struct dbc_frame){.id = id, .bridge_kind = -1};
      snprintf(cur->name, sizeof cur->name, "%s", name);
    } else if (cur && sscanf(line, " SG_ %63s :", name) == 1 &&
               strstr(line, "SG_ ")) {
      cur->to_bridge |= names_bridge(line);
      double lo, hi;
      const char *range = strchr(line, '[');
      if (!strcmp(name, "Counter") && range &&
          sscanf(range, "[%lf|%lf]", &lo, &hi) == 2) {
        assert_true(lo == 0.0);
        cur->counter_modulo = (unsigned)hi + 1u;
      }
    } else if (sscanf(line, "BA_ \"BridgeKind\" BO_ %u %u;", &id, &kind) == 2) {
      struct dbc_frame *fr = frame_of_id(id);
      assert_non_null(fr);
      assert_int_equal(fr->bridge_kind, -1); /* given once */
      fr->bridge_kind = (int)kind;
    } else if (line[0] != ' ') {
      cur = NULL; /* a frame's signals end with its block */
    }
  }
  free(line);
  fclose(f);
  return n_frames > 0 ? 0 : -1;
}

static void test_every_frame_to_the_bridge_has_one_kind(void **state) {
  (void)state;
  size_t kinds = 0;
  for (size_t i = 0; i < n_frames; i++) {
    const struct dbc_frame *d = &frames[i];
    const struct sensor_kind *found = sensor_kind_of_id(d->id);
    if (!d->to_bridge) {
      /* the bridge's own frames (TEAM_COMMAND) are no kind */
      assert_int_equal(d->bridge_kind, -1);
      assert_null(found);
      continue;
    }
    kinds++;
    assert_true(d->bridge_kind >= 0 && d->bridge_kind < FRAME_KIND_COUNT);
    const struct sensor_kind *k = sensor_kinds[d->bridge_kind];
    assert_ptr_equal(found, k);
    assert_int_equal(k->kind, d->bridge_kind);
    assert_int_equal(k->id_first, d->id);
    assert_int_equal(k->id_last, d->id);
    char lower[64];
    size_t n = 0;
    for (; d->name[n]; n++)
      lower[n] = (char)tolower((unsigned char)d->name[n]);
    lower[n] = '\0';
    assert_string_equal(k->name, lower);
    assert_int_not_equal(d->counter_modulo, 0);
    assert_int_equal(sensor_counter_modulo(k), d->counter_modulo);
  }
  /* and no kind without its frame */
  assert_int_equal(kinds, FRAME_KIND_COUNT);
  for (int k = 0; k < FRAME_KIND_COUNT; k++) {
    assert_int_equal(sensor_kinds[k]->kind, k);
    const struct dbc_frame *d = frame_of_id(sensor_kinds[k]->id_first);
    assert_non_null(d);
    assert_int_equal(d->bridge_kind, k);
  }
}

/* Today's numbers, which the stats JSON's and the status line's order of the
 * kinds follow (the DBC's BridgeKind attributes keep them). */
static void test_numbers_stay(void **state) {
  (void)state;
  assert_int_equal(FRAME_PULSE_DETECTION, 0);
  assert_int_equal(FRAME_WHEEL_ENCODERS, 1);
  assert_int_equal(FRAME_NODE_STATUS, 2);
  assert_int_equal(FRAME_BEARING, 3);
  assert_int_equal(FRAME_RANGE, 4);
  assert_int_equal(FRAME_TRACK_ENCODERS, 5);
  assert_int_equal(FRAME_BEACON_SURVEY, 6);
  assert_int_equal(FRAME_SONAR, 7);
  assert_int_equal(FRAME_AIR_TEMPERATURE, 8);
  assert_int_equal(FRAME_KIND_COUNT, 9);
}

/* The ranks are distinct, and exactly one kind, of the largest rank, has no
 * condition: the rule always ends on a clock. */
static void test_timebase_ranks_well_formed(void **state) {
  (void)state;
  unsigned largest = 0, unconditional = 0, last_resort_rank = 0;
  for (int k = 0; k < FRAME_KIND_COUNT; k++) {
    const struct sensor_kind *a = sensor_kinds[k];
    if (a->timebase_rank == 0) {
      assert_null(a->timebase_if);
      continue;
    }
    for (int j = 0; j < k; j++)
      assert_int_not_equal(a->timebase_rank, sensor_kinds[j]->timebase_rank);
    if (a->timebase_rank > largest)
      largest = a->timebase_rank;
    if (!a->timebase_if) {
      unconditional++;
      last_resort_rank = a->timebase_rank;
    }
  }
  assert_int_equal(unconditional, 1);
  assert_int_equal(last_resort_rank, largest);
}

static struct estimator E;

static enum frame_kind timebase_of(unsigned beacons, unsigned bearing,
                                   unsigned range, bool sonar) {
  memset(&E, 0, sizeof E);
  E.blcfg.beacon_count = beacons;
  E.blcfg.bearing_beacon_count = bearing;
  E.blcfg.range_beacon_count = range;
  E.sonar.on = sonar;
  enum frame_kind k = sensor_timebase_kind(&E);
  assert_ptr_equal(estimator_ref_clock(&E), &E.clock[k]);
  return k;
}

/* The rule as the chain of cases of before (timebase.c): pulse receiver if
 * the site has ultrasonic beacons, else bearing sensor if bearing beacons,
 * else sonar ring on a ring site without range beacons, else range receiver. */
static void test_timebase_rule(void **state) {
  (void)state;
  for (unsigned m = 0; m < 16; m++) {
    unsigned beacons = m & 1u ? 6 : 0, bearing = m & 2u ? 4 : 0,
             range = m & 4u ? 4 : 0;
    bool sonar = m & 8u;
    enum frame_kind want = beacons           ? FRAME_PULSE_DETECTION
                           : bearing         ? FRAME_BEARING
                           : !range && sonar ? FRAME_SONAR
                                             : FRAME_RANGE;
    assert_int_equal(timebase_of(beacons, bearing, range, sonar), want);
  }
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_every_frame_to_the_bridge_has_one_kind),
      cmocka_unit_test(test_numbers_stay),
      cmocka_unit_test(test_timebase_ranks_well_formed),
      cmocka_unit_test(test_timebase_rule),
  };
  return cmocka_run_group_tests(tests, read_dbc, NULL);
}
