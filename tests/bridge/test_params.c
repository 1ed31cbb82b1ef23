/*
 * cmocka: the MAVLink parameters (bridge/params.c) over the site schema's
 * SITE_PARAMS: every parameter is a site key the parser knows, with its
 * range; names fit PARAM_VALUE and are found back; a value outside the
 * key's range or an INT32 that is not whole is refused with the config
 * untouched; a float from the wire is read as its shortest decimal; the
 * override file is written as a site-file fragment the site parser reads
 * back over a site file, and rewriting it keeps its other lines.
 */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <cmocka.h>

#include "config.h"
#include "params.h"

#define SITE "hw_sim/beaconloc_sim/data/scenarios/kleeman-lab.ini"

static void load_site(struct bridge_config *c)
{
    char err[CONFIG_ERR_LEN];
    config_defaults(c);
    assert_int_equal(config_load_file(c, SITE, err, sizeof err), 0);
}

static void test_table(void **state)
{
    (void)state;
    assert_true(PARAMS_COUNT >= 40);
    assert_null(params_at(-1));
    assert_null(params_at(PARAMS_COUNT));
    struct bridge_config c;
    config_defaults(&c);
    for (int i = 0; i < PARAMS_COUNT; i++) {
        const struct param_desc *p = params_at(i);
        assert_non_null(p);
        assert_true(strlen(p->name) >= 1 && strlen(p->name) <= PARAMS_NAME_MAX);
        assert_int_equal(params_find(p->name), i);
        for (int j = 0; j < i; j++) assert_string_not_equal(params_at(j)->name, p->name);
        /* the default is inside the range; the bounds are where the schema says */
        double v = params_get(&c, i);
        assert_true(isfinite(v));
        assert_true(p->lo_open ? v > p->lo : v >= p->lo);
        assert_true(v <= p->hi);
    }
    assert_int_equal(params_find("NSE_GATE") >= 0, 1);
    assert_int_equal(params_find("nse_gate"), -1); /* the protocol compares exactly */
    assert_int_equal(params_find("NO_SUCH"), -1);
    assert_int_equal(params_find(NULL), -1);
}

static void test_set_checks_the_range(void **state)
{
    (void)state;
    struct bridge_config c, before;
    load_site(&c);
    int gate = params_find("NSE_GATE"); /* [noise] gate_sigma, (0, 1000] */
    const struct param_desc *p = params_at(gate);
    assert_string_equal(p->section, "noise");
    assert_string_equal(p->key, "gate_sigma");
    assert_false(p->is_int);
    assert_int_equal(params_set(&c, gate, 0.05), 0);
    assert_true(c.gate_sigma == 0.05);
    assert_true(params_get(&c, gate) == 0.05);
    before = c;
    assert_int_equal(params_set(&c, gate, 0.0), -ERANGE); /* lower bound excluded */
    assert_int_equal(params_set(&c, gate, 1000.5), -ERANGE);
    assert_int_equal(params_set(&c, gate, NAN), -EINVAL);
    assert_int_equal(params_set(&c, gate, INFINITY), -EINVAL);
    assert_int_equal(params_set(&c, PARAMS_COUNT, 1.0), -EINVAL);
    assert_memory_equal(&c, &before, sizeof c);
    assert_int_equal(params_set(&c, gate, 1000.0), 0); /* upper bound included */
    int iters = params_find("TUN_IEKF_ITER"); /* INT32, [1, 20] */
    assert_true(params_at(iters)->is_int);
    before = c;
    assert_int_equal(params_set(&c, iters, 2.5), -EINVAL);
    assert_int_equal(params_set(&c, iters, 21.0), -ERANGE);
    assert_memory_equal(&c, &before, sizeof c);
    assert_int_equal(params_set(&c, iters, 7.0), 0);
    assert_int_equal(c.tuning.iekf_max_iterations, 7);
    assert_true(params_get(&c, iters) == 7.0);
}

static void test_from_wire(void **state)
{
    (void)state;
    assert_true(params_from_wire(0.0002f) == 0.0002);
    assert_true(params_from_wire(0.05f) == 0.05);
    assert_true(params_from_wire(343.2f) == 343.2);
    assert_true(params_from_wire(7.0f) == 7.0);
    assert_true(params_from_wire(1e-8f) == 1e-8);
    /* a float that needs all its digits still reads back as itself */
    float odd = 0.1234567f;
    assert_true((float)params_from_wire(odd) == odd);
}

static void read_file(const char *path, char *buf, size_t len)
{
    FILE *f = fopen(path, "r");
    assert_non_null(f);
    size_t n = fread(buf, 1, len - 1, f);
    buf[n] = '\0';
    fclose(f);
}

static void test_override_file(void **state)
{
    (void)state;
    char path[] = "/tmp/test_params_XXXXXX";
    int fd = mkstemp(path);
    assert_true(fd >= 0);
    close(fd);
    unlink(path); /* a file that does not exist yet */
    int gate = params_find("NSE_GATE"), iters = params_find("TUN_IEKF_ITER");
    int rate = params_find("BR_ODOM_RATE");
    assert_int_equal(params_save(path, gate, 0.05), 0);
    assert_int_equal(params_save(path, iters, 6), 0);
    assert_int_equal(params_save(path, gate, 0.25), 0); /* replaced, not repeated */
    assert_int_equal(params_save(path, rate, 50), 0);
    char text[2048];
    read_file(path, text, sizeof text);
    assert_non_null(strstr(text, "[noise]\ngate_sigma = 0.25\n"));
    assert_null(strstr(text, "0.05"));
    assert_non_null(strstr(text, "[tuning]\niekf_max_iterations = 6\n"));
    assert_non_null(strstr(text, "[bridge]\nodometry_rate_hz = 50\n"));
    /* an operator's comment and a key of the same section written by hand stay */
    FILE *f = fopen(path, "a");
    assert_non_null(f);
    fputs("# kept\n[noise]\nsigma_arrival_s = 0.0003\n", f);
    fclose(f);
    assert_int_equal(params_save(path, params_find("NSE_SOS"), 340.5), 0);
    read_file(path, text, sizeof text);
    assert_non_null(strstr(text, "# kept\n"));
    assert_non_null(strstr(text, "sigma_arrival_s = 0.0003\n"));
    assert_non_null(strstr(text, "speed_of_sound_mps = 340.5\n"));
    /* the site parser reads it over the site file: the saved values win */
    struct bridge_config c;
    load_site(&c);
    char err[CONFIG_ERR_LEN];
    assert_int_equal(config_load_file(&c, path, err, sizeof err), 0);
    assert_true(c.gate_sigma == 0.25);
    assert_int_equal(c.tuning.iekf_max_iterations, 6);
    assert_true(c.odometry_rate_hz == 50.0);
    assert_true(c.speed_of_sound_mps == 340.5);
    assert_true(c.sigma_arrival_s == 0.0003);
    assert_int_equal(c.beacon_count, 6); /* the site's, untouched */
    assert_int_equal(params_save(path, PARAMS_COUNT, 1.0), -EINVAL);
    assert_int_equal(params_save("/nonexistent-dir/params.ini", gate, 1.0), -ENOENT);
    unlink(path);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_table),
        cmocka_unit_test(test_set_checks_the_range),
        cmocka_unit_test(test_from_wire),
        cmocka_unit_test(test_override_file),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
