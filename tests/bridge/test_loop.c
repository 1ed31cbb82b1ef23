/*
 * cmocka: the event loop (bridge/loop.c): each ready descriptor's own
 * handler runs with its own object (no fd comparisons anywhere), write
 * handlers only for objects that have one, and an object a handler took
 * out of the set in the same turn is not called.
 */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <string.h>
#include <unistd.h>
#include <sys/eventfd.h>
#include <cmocka.h>

#include "loop.h"

struct probe {
    struct pollable p;    /* first member */
    int reads, writes;
    struct pollable *victim; /* taken out of the set by on_read */
    struct loop *loop;
};

static void on_read(struct pollable *p)
{
    struct probe *pr = p->owner;
    pr->reads++;
    uint64_t v;
    if (read(p->fd, &v, sizeof v) < 0)
        return;
    if (pr->victim)
        loop_del(pr->loop, pr->victim);
}

static void on_write(struct pollable *p)
{
    struct probe *pr = p->owner;
    pr->writes++;
}

static int make_ready(void)
{
    int fd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
    assert_true(fd >= 0);
    uint64_t one = 1;
    assert_int_equal(write(fd, &one, sizeof one), (ssize_t)sizeof one);
    return fd;
}

static void test_each_handler_with_its_object(void **state)
{
    (void)state;
    struct loop l;
    assert_int_equal(loop_open(&l), 0);
    struct probe a = { .p = { .fd = -1, .on_read = on_read }, .loop = &l };
    struct probe b = { .p = { .fd = -1, .on_read = on_read, .on_write = on_write }, .loop = &l };
    a.p.owner = &a;
    b.p.owner = &b;
    int fa = make_ready(), fb = make_ready();
    assert_int_equal(loop_add(&l, &a.p, fa, "a"), 0);
    assert_int_equal(loop_add(&l, &b.p, fb, "b"), 0);
    assert_int_equal(a.p.fd, fa);
    assert_int_equal(loop_run_once(&l, 1000), 2);
    assert_int_equal(a.reads, 1);
    assert_int_equal(a.writes, 0);
    assert_int_equal(b.reads, 1);
    assert_int_equal(b.writes, 1); /* an eventfd is always writable */
    /* drained: a is not readable any more, b still writable */
    assert_int_equal(loop_run_once(&l, 0), 1);
    assert_int_equal(a.reads, 1);
    assert_int_equal(b.writes, 2);
    assert_int_equal(loop_del(&l, &b.p), 0);
    assert_int_equal(b.p.fd, -1);
    assert_int_equal(loop_run_once(&l, 0), 0);
    assert_int_equal(loop_del(&l, &b.p), 0); /* again: nothing to do */
    close(fa);
    close(fb);
    loop_close(&l);
}

/* Both ready; whichever runs first takes the other out: the other's
 * handler does not run in that turn. */
static void test_removed_in_the_same_turn_is_skipped(void **state)
{
    (void)state;
    struct loop l;
    assert_int_equal(loop_open(&l), 0);
    struct probe a = { .p = { .fd = -1, .on_read = on_read }, .loop = &l };
    struct probe b = { .p = { .fd = -1, .on_read = on_read }, .loop = &l };
    a.p.owner = &a;
    b.p.owner = &b;
    a.victim = &b.p;
    b.victim = &a.p;
    int fa = make_ready(), fb = make_ready();
    assert_int_equal(loop_add(&l, &a.p, fa, "a"), 0);
    assert_int_equal(loop_add(&l, &b.p, fb, "b"), 0);
    assert_int_equal(loop_run_once(&l, 1000), 2);
    assert_int_equal(a.reads + b.reads, 1);
    close(fa);
    close(fb);
    loop_close(&l);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_each_handler_with_its_object),
        cmocka_unit_test(test_removed_in_the_same_turn_is_skipped),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
