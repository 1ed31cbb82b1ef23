/*
 * cmocka: a team site's keys (bridge/config.c, the site schema's [team],
 * [robot] skid_factor, [noise] slip_*): the millibots sites load as team
 * sites with the values written in them and map onto the library's config
 * (range.team_site derived from [team] robots, the skid-steer fields); the
 * [team] defaults are the library's (bl_team_params_default); every bad
 * value is refused with "file:line: [section] key: why".
 */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <math.h>
#include <string.h>
#include <unistd.h>
#include <cmocka.h>

#include "beaconloc.h"
#include "beaconloc/team.h"
#include "config.h"
#include "site_to_lib.h"
#include "team.h"

#define ROOM "hw_sim/beaconloc_sim/data/scenarios/millibots-room.ini"
#define CORRIDOR "hw_sim/beaconloc_sim/data/scenarios/millibots-corridor.ini"

/* A team site with its [team] section from line 10 on. */
static const char *team_body =
    "[beacons]\n"                /* 1 */
    "count = 0\n"                /* 2 */
    "[range_beacons]\n"          /* 3 */
    "count = 0\n"                /* 4 */
    "[robot]\n"                  /* 5 */
    "wheel_base_m = 0.08\n"      /* 6 */
    "skid_factor = 1.5\n"        /* 7 */
    "[noise]\n"                  /* 8 */
    "slip_heading_rad_per_sqrt_rad = 0.05\n" /* 9 */
    "[team]\n"                   /* 10 */
    "robots = 4\n";              /* 11 */

static char path[64];

static int make_file(const char *body, const char *more)
{
    snprintf(path, sizeof path, "/tmp/test_team_config_XXXXXX");
    int fd = mkstemp(path);
    if (fd < 0)
        return -1;
    FILE *f = fdopen(fd, "w");
    fputs(body, f);
    fputs(more, f);
    fclose(f);
    return 0;
}

static int teardown(void **state)
{
    (void)state;
    if (path[0])
        unlink(path);
    path[0] = '\0';
    return 0;
}

static int load(const char *file, struct bridge_config *cfg, char *err)
{
    config_defaults(cfg);
    return config_load_file(cfg, file, err, CONFIG_ERR_LEN);
}

/* team_body + more must fail with "<file>:<expect>". */
static void expect_error(const char *more, const char *expect)
{
    assert_int_equal(make_file(team_body, more), 0);
    struct bridge_config cfg;
    char err[CONFIG_ERR_LEN];
    assert_int_equal(load(path, &cfg, err), -1);
    char want[CONFIG_ERR_LEN + 64];
    snprintf(want, sizeof want, "%s%s", path, expect);
    if (strncmp(err, want, strlen(want)) != 0)
        fail_msg("error\n  got:  %s\n  want: %s...", err, want);
    teardown(NULL);
}

/* body alone must fail with "<file>:<expect>". */
static void expect_error_body(const char *body, const char *expect)
{
    assert_int_equal(make_file(body, ""), 0);
    struct bridge_config cfg;
    char err[CONFIG_ERR_LEN];
    assert_int_equal(load(path, &cfg, err), -1);
    char want[CONFIG_ERR_LEN + 64];
    snprintf(want, sizeof want, "%s%s", path, expect);
    if (strncmp(err, want, strlen(want)) != 0)
        fail_msg("error\n  got:  %s\n  want: %s...", err, want);
    teardown(NULL);
}

static void test_millibots_sites_are_team_sites(void **state)
{
    (void)state;
    const char *files[] = {ROOM, CORRIDOR};
    for (int i = 0; i < 2; i++) {
        struct bridge_config cfg;
        char err[CONFIG_ERR_LEN];
        if (load(files[i], &cfg, err) != 0)
            fail_msg("%s", err);
        assert_true(config_is_team(&cfg));
        assert_int_equal(cfg.team.robots, 4);
        assert_int_equal(cfg.team.origin_robot, 1);
        assert_int_equal(cfg.team.axis_robot, 2);
        assert_int_equal(cfg.team.leader, 1);
        assert_int_equal(cfg.team.system_id_first, 101);
        assert_true(cfg.team.survey_s == 2.0 && cfg.team.role_timeout_s == 1.0 &&
                    cfg.team.lost_s == 3.0);
        assert_true(cfg.skid_factor == 1.5);
        assert_true(cfg.sigma_distance_per_m == 0.02);
        assert_true(cfg.slip_heading_rad_per_sqrt_rad == 0.05);
        /* onto the library: a team site, the skid-steer odometry */
        bl_config c;
        assert_int_equal(estimator_make_config(&cfg, &c, err, sizeof err), 0);
        assert_int_equal(c.range.team_site, 1);
        assert_true(fabs((double)c.wheels.skid_factor - 1.5) < 1e-6);
        assert_true(fabs((double)c.wheels.slip_heading_rad_per_sqrt_rad - 0.05) < 1e-6);
        assert_true(c.wheels.slip_lateral_m_per_sqrt_m == 0);
        assert_true(fabs((double)c.wheels.sigma_distance_per_m - 0.02) < 1e-6);
        /* and the team parameters */
        bl_team_params p;
        team_params_from_site(&cfg, &p);
        assert_int_equal(p.robots, 4);
        assert_int_equal(p.origin_robot, 1);
        assert_int_equal(p.axis_robot, 2);
        assert_true(fabs((double)p.survey_s - 2.0) < 1e-6);
        assert_true(fabs((double)p.lost_s - 3.0) < 1e-6);
    }
}

/* A site without [team] is no team site; the library's team_site stays 0
 * and the skid-steer fields their differential-drive defaults. */
static void test_other_sites_are_not(void **state)
{
    (void)state;
    struct bridge_config cfg;
    char err[CONFIG_ERR_LEN];
    if (load("hw_sim/beaconloc_sim/data/scenarios/marvelmind.ini", &cfg, err) != 0)
        fail_msg("%s", err);
    assert_false(config_is_team(&cfg));
    bl_config c;
    assert_int_equal(estimator_make_config(&cfg, &c, err, sizeof err), 0);
    assert_int_equal(c.range.team_site, 0);
    assert_true(c.wheels.skid_factor == 1 && c.wheels.slip_heading_rad_per_sqrt_rad == 0);
}

/* The schema's [team] defaults are the library's team defaults. */
static void test_team_defaults_are_the_librarys(void **state)
{
    (void)state;
    struct bridge_config cfg;
    config_defaults(&cfg);
    assert_int_equal(cfg.team.robots, 0);
    bl_team_params lib;
    assert_int_equal(bl_team_params_default(&lib), BL_OK);
    assert_int_equal(cfg.team.origin_robot, (int)lib.origin_robot);
    assert_int_equal(cfg.team.axis_robot, (int)lib.axis_robot);
    assert_true(fabs(cfg.team.survey_s - (double)lib.survey_s) < 1e-6);
    assert_true(fabs(cfg.team.role_timeout_s - (double)lib.role_timeout_s) < 1e-6);
    assert_true(fabs(cfg.team.lost_s - (double)lib.lost_s) < 1e-6);
    bl_config c;
    bl_config_default(&c);
    assert_true(fabs(cfg.skid_factor - (double)c.wheels.skid_factor) < 1e-9);
    assert_true(fabs(cfg.slip_heading_rad_per_sqrt_rad -
                     (double)c.wheels.slip_heading_rad_per_sqrt_rad) < 1e-9);
    assert_true(fabs(cfg.slip_lateral_m_per_sqrt_m - (double)c.wheels.slip_lateral_m_per_sqrt_m) <
                1e-9);
    /* the minimal team file loads, with its defaults */
    assert_int_equal(make_file(team_body, ""), 0);
    char err[CONFIG_ERR_LEN];
    if (load(path, &cfg, err) != 0)
        fail_msg("%s", err);
    assert_int_equal(cfg.team.robots, 4);
    assert_int_equal(cfg.team.system_id_first, 101);
    assert_int_equal(team_system_id(&cfg, 1), 101);
    assert_int_equal(team_system_id(&cfg, 4), 104);
    teardown(NULL);
}

static void test_team_errors_name_the_key(void **state)
{
    (void)state;
    expect_error("robots = 5\n", ":12: [team] robots: given twice (first on line 11)");
    expect_error("system_id_first = 0\n", ":12: [team] system_id_first: 0 out of range 1..255");
    expect_error("bogus = 1\n", ":12: [team] bogus: unknown key");
    expect_error("survey_s = 0\n", ":12: [team] survey_s: 0 out of range (0..600]");
    expect_error("[robot]\nskid_factor = 0.9\n", ":13: [robot] skid_factor: given twice");
    /* the checks of the whole */
    expect_error("origin_robot = 5\n", ":12: [team] origin_robot: 5 beyond robots = 4");
    expect_error("leader = 6\n", ":12: [team] leader: 6 beyond robots = 4");
    expect_error("axis_robot = 1\n",
                 ":12: [team] axis_robot: 1: one of robots 1..4 other than origin_robot 1");
    expect_error("lost_s = 0.5\n", ":12: [team] lost_s: 0.5 s not above role_timeout_s 1 s");
    expect_error("system_id_first = 253\n",
                 ":12: [team] system_id_first: 253: robot 4 would be system id 256, above 255");
    /* [bridge] system_id 1 (the default) among the robots' 1..4 */
    expect_error("system_id_first = 1\n",
                 ":12: [team] system_id_first: 1: the robots' system ids 1..4 include [bridge] "
                 "system_id 1");
    /* the skid-steer keys' ranges */
    expect_error_body("[robot]\nskid_factor = 0.9\n", ":2: [robot] skid_factor: 0.9 out of range");
    expect_error_body("[noise]\nslip_lateral_m_per_sqrt_m = 1\n",
                      ":2: [noise] slip_lateral_m_per_sqrt_m: 1 out of range");
    /* robots: beyond the schema's largest, a team of two */
    expect_error_body("[beacons]\ncount = 0\n[team]\nrobots = 9\n",
                      ":4: [team] robots: 9 out of range 0..8");
    expect_error_body("[beacons]\ncount = 0\n[team]\nrobots = 2\n",
                      ":4: [team] robots: 2: a team needs 3..8 robots");
    /* fixed beacons on a team site */
    expect_error_body("[beacons]\ncount = 0\n[range_beacons]\ncount = 3\n"
                      "[range_beacon1]\nx_m = 0\ny_m = 0\nz_m = 1\n"
                      "[range_beacon2]\nx_m = 3\ny_m = 0\nz_m = 1\n"
                      "[range_beacon3]\nx_m = 0\ny_m = 3\nz_m = 1\n"
                      "[team]\nrobots = 3\n",
                      ":4: [range_beacons] count: 3 on a team site ([team] robots = 3)");
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_millibots_sites_are_team_sites),
        cmocka_unit_test(test_other_sites_are_not),
        cmocka_unit_test(test_team_defaults_are_the_librarys),
        cmocka_unit_test_teardown(test_team_errors_name_the_key, teardown),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
