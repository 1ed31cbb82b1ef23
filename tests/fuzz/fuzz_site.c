/*
 * beaconloc fuzzing — the site file, the whole path the daemon takes with
 * it (bridge/main.c at start, bridge/control.c on SIGHUP):
 *   config_defaults -> config_load_file (libinih, every section and key,
 *   [tuning] included, the consistency check) -> estimator_init (the
 *   library's config, bl_config_check, the sequencer's config) and
 *   estimator_reconfigure of a running estimator (SIGHUP).
 * The input is the file, written to a memfd and loaded by its path.
 *
 * Invariants: a failure leaves a message; a file that loads passes
 * config_check again; estimator_reconfigure that fails leaves the
 * estimator byte-identical (its contract); one that succeeds keeps the
 * filter when the geometry is the same (return 0) and re-initialises it
 * otherwise (1).
 */
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#include "config.h"
#include "estimator.h"
#include "fuzz_common.h"
#include "log.h"

int LLVMFuzzerInitialize(int *argc, char ***argv);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static int memfd = -1;
static char memfd_path[64];
static struct bridge_config site;          /* kleeman-lab */
static struct estimator running_template;  /* estimator_init'ed on it */
static struct estimator running, before;

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
    (void)argc;
    (void)argv;
    log_set_level(LOG_ERROR);
    memfd = memfd_create("fuzz_site", MFD_CLOEXEC);
    if (memfd < 0)
        abort();
    snprintf(memfd_path, sizeof memfd_path, "/proc/self/fd/%d", memfd);
    char err[CONFIG_ERR_LEN];
    config_defaults(&site);
    if (config_load_file(&site, FUZZ_SITE, err, sizeof err) != 0 ||
        estimator_init(&running_template, &site, err, sizeof err) != 0) {
        fprintf(stderr, "fuzz_site: %s\n", err);
        abort();
    }
    return 0;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (ftruncate(memfd, 0) != 0 || pwrite(memfd, data, size, 0) != (ssize_t)size)
        abort();
    struct bridge_config cfg;
    config_defaults(&cfg);
    char err[CONFIG_ERR_LEN];
    err[0] = '\0';
    if (config_load_file(&cfg, memfd_path, err, sizeof err) != 0) {
        FUZZ_CHECK(err[0] != '\0' && memchr(err, '\0', sizeof err), "no message");
        return 0;
    }
    char err2[CONFIG_ERR_LEN];
    FUZZ_CHECK(config_check(&cfg, err2, sizeof err2) == 0,
               "loaded, but config_check: %s", err2);

    static struct estimator e;
    err[0] = '\0';
    int rc = estimator_init(&e, &cfg, err, sizeof err);
    FUZZ_CHECK(rc == 0 || rc == -1, "estimator_init: %d", rc);
    if (rc != 0)
        FUZZ_CHECK(err[0] != '\0', "estimator_init failed without a message");
    bl_config lib;
    int rc2 = estimator_make_config(&cfg, &lib, err2, sizeof err2);
    /* init may refuse more (the sequencer's windows), never less */
    FUZZ_CHECK(rc != 0 || rc2 == 0, "init accepted what make_config refused: %s", err2);
    if (rc == 0)
        FUZZ_CHECK(bl_config_check(&lib, NULL) == BL_OK, "estimator accepted a bad config");

    /* SIGHUP on a running daemon */
    memcpy(&running, &running_template, sizeof running);
    memcpy(&before, &running, sizeof before);
    err[0] = '\0';
    rc = estimator_reconfigure(&running, &cfg, err, sizeof err);
    if (rc < 0) {
        FUZZ_CHECK(err[0] != '\0', "reconfigure failed without a message");
        FUZZ_CHECK(!memcmp(&running, &before, sizeof running),
                   "failed reconfigure changed the estimator: %s", err);
    } else {
        FUZZ_CHECK(rc == (config_same_geometry(&site, &cfg) ? 0 : 1),
                   "reconfigure returned %d, same geometry %d", rc,
                   config_same_geometry(&site, &cfg));
    }
    return 0;
}
