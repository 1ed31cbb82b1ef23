/* cmocka tests of the sonar correctors (sonar.h; Hoppenot & Colle 1997
 * §3.1 pin-point, §3.2 with memory) in the room of sonar_world.h: known
 * pose offsets recovered from exact ranges, the stopping rules and the
 * per-axis fall-back (steps 6-8), the end-point case of eq. 4,
 * the 25 cm gate, the 20° incidence gate, bad data counted, bad input
 * refused with the pose and the memory untouched. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <string.h>
#include <math.h>
#include <cmocka.h>

#include "beaconloc.h"
#include "sonar_world.h"
#include "test_rng.h"

#define HALF_BEAM_RAD (15.0 * 3.141592653589793 / 180.0)

/* The burst of the seven used sensors at the true pose: along the axis
 * (eq. 1's impact model, what the memory corrector places; specular 0) or
 * the sonar's specular physics (the first echo inside the cone, the
 * perpendicular foot or a wall's end: what the simulator and a Polaroid
 * return, and what the pin-point corrector models; specular 1). Returns the
 * number of ranges. */
static uint32_t burst_of(double x, double y, double th, int specular, bl_sonar_range *b)
{
    uint32_t n = 0;
    for (int i = 0; i < WORLD_SENSORS; ++i) {
        if (i == 4) continue; /* the unused rear sensor */
        const double r = specular ? world_specular_range(world_segments, WORLD_SEGMENTS, i, x, y, th, HALF_BEAM_RAD)
                                  : world_axis_range(world_segments, WORLD_SEGMENTS, i, x, y, th);
        b[n].sensor = (uint32_t)i;
        b[n].range_m = (bl_real)(isnan(r) ? 0 : r);
        b[n].flags = isnan(r) ? BL_SONAR_NO_ECHO : 0;
        b[n].user_reference = NULL;
        ++n;
    }
    return n;
}

/* A known position offset is recovered from exact specular ranges, at many
 * poses of the room; the heading, which a specular range sees only through
 * the ring's 0.2 m lever arm, stays near the odometry's (its prior). */
static void test_pinpoint_recovers_offset(void **state)
{
    (void)state;
    bl_map map;
    bl_sonar_ring ring;
    world_map(&map);
    world_ring(&ring);
    rng_seed(12);
    int exact = 0, trials = 0;
    for (int trial = 0; trial < 40; ++trial) {
        const double x = 1.5 + 2.5 * rng_uniform(), y = 1.0 + 2.0 * rng_uniform();
        const double th = -3.0 + 6.0 * rng_uniform();
        bl_sonar_range b[8];
        const uint32_t n = burst_of(x, y, th, 1, b);
        /* odometric pose: 8 cm off in a random direction, the heading true */
        const double a = 6.283185307179586 * rng_uniform();
        bl_pose p = {(bl_real)(x + 0.08 * cos(a)), (bl_real)(y + 0.08 * sin(a)), (bl_real)th};
        bl_pinpoint_params prm;
        bl_pinpoint_default(&prm);
        prm.epsilon_cost_m2 = (bl_real)1e-10;
        prm.epsilon_grad = (bl_real)1e-7;
        bl_pinpoint_result r;
        assert_int_equal(bl_pinpoint_correct(&map, &ring, b, n, &prm, &p, &r), BL_OK);
        assert_true((double)r.cost_after_m2 <= (double)r.cost_before_m2);
        if (r.matched < 3) continue; /* too few echoes here: nothing to check */
        ++trials;
        const double ex = (double)p.x_m - x, ey = (double)p.y_m - y;
        const double eth = remainder((double)p.theta_rad - th, 6.283185307179586);
        assert_true(fabs(eth) < 0.02);
        if (r.outcome == BL_PINPOINT_CONVERGED && hypot(ex, ey) < 0.01) ++exact;
    }
    /* every pose with two walls at an angle in its echoes; the rest see
     * parallel walls only, or match a wall's end with another one near a
     * corner at the odometric pose (the paper's local minimum) */
    assert_true(trials >= 20);
    assert_true(exact >= trials * 3 / 4);
}

/* The specular echo (the perpendicular foot inside the cone) is not where
 * eq. 1 puts the impact (on the beam axis): at the true pose with exact
 * specular ranges and the heading up to 14° off every wall's normal, the
 * corrector leaves the pose where it is (F = 0 there). With the axis model
 * the impacts lie up to d (1 − cos 15°) short of the walls and the pose
 * moved by centimetres and degrees at every burst. */
static void test_pinpoint_specular_true_pose_is_kept(void **state)
{
    (void)state;
    bl_map map;
    bl_sonar_ring ring;
    world_map(&map);
    world_ring(&ring);
    const double deg = 3.141592653589793 / 180.0;
    for (int k = -14; k <= 14; k += 4) {
        const double x = 2.0, y = 1.5, th = k * deg;
        bl_sonar_range b[8];
        const uint32_t n = burst_of(x, y, th, 1, b);
        bl_pose p = {(bl_real)x, (bl_real)y, (bl_real)th};
        bl_pinpoint_result r;
        assert_int_equal(bl_pinpoint_correct(&map, &ring, b, n, NULL, &p, &r), BL_OK);
        assert_true(r.matched >= 3);
        assert_true((double)r.cost_before_m2 < 1e-10);
        assert_true(hypot((double)p.x_m - x, (double)p.y_m - y) < 1e-3);
        assert_true(fabs((double)p.theta_rad - th) < 1e-3);
    }
}

/* The paper's own impact (eq. 1, BL_PINPOINT_IMPACT_AXIS): with ranges
 * heard along the beam axes (walls that echo at any incidence, as the
 * paper's real ones did: §5.2), an odometric heading 4° off is turned back
 * by the burst alone, the position kept. With the specular echo model (the
 * default) the same burst leaves most of the heading error: a range matched
 * at its foot sees the heading through the ring's lever arm only. */
static void test_pinpoint_axis_observes_heading(void **state)
{
    (void)state;
    bl_map map;
    bl_sonar_ring ring;
    world_map(&map);
    world_ring(&ring);
    const double deg = 3.141592653589793 / 180.0;
    const double x = 1.8, y = 2.0, th = -0.3;
    bl_sonar_range b[8];
    const uint32_t n = burst_of(x, y, th, 0, b);
    for (uint32_t k = 0; k < n; ++k) assert_int_equal(b[k].flags, 0); /* every beam on a wall */
    for (int sign = -1; sign <= 1; sign += 2) {
        bl_pinpoint_params prm;
        bl_pinpoint_default(&prm);
        assert_int_equal(prm.impact, BL_PINPOINT_IMPACT_ECHO);
        prm.epsilon_cost_m2 = (bl_real)1e-10;
        prm.epsilon_grad = (bl_real)1e-7;
        prm.heading_sigma_rad = 0; /* the paper's F */
        prm.impact = BL_PINPOINT_IMPACT_AXIS;
        bl_pose p = {(bl_real)x, (bl_real)y, (bl_real)(th + sign * 4 * deg)};
        bl_pinpoint_result r;
        assert_int_equal(bl_pinpoint_correct(&map, &ring, b, n, &prm, &p, &r), BL_OK);
        assert_int_equal(r.outcome, BL_PINPOINT_CONVERGED);
        assert_true(r.matched >= 5);
        assert_true(fabs((double)p.theta_rad - th) < 0.2 * deg);
        assert_true(hypot((double)p.x_m - x, (double)p.y_m - y) < 0.01);
        /* the paper's minimiser (descent_rate 0.1, §3.1) gets there too,
         * in its small gradient steps: more iterations than Gauss–Newton */
        const uint32_t gn_iterations = r.iterations;
        prm.descent_rate = (bl_real)0.1;
        prm.max_iterations = 100;
        p = (bl_pose){(bl_real)x, (bl_real)y, (bl_real)(th + sign * 4 * deg)};
        assert_int_equal(bl_pinpoint_correct(&map, &ring, b, n, &prm, &p, &r), BL_OK);
        assert_int_equal(r.outcome, BL_PINPOINT_CONVERGED);
        assert_true(r.iterations > gn_iterations);
        assert_true(fabs((double)p.theta_rad - th) < 0.3 * deg);
        assert_true(hypot((double)p.x_m - x, (double)p.y_m - y) < 0.01);
        prm.descent_rate = 0;
        prm.max_iterations = 10;
        /* the echo model: ranges along the axes are no specular echoes; the
         * matched ones (feet and ends within the 25 cm gate) turn the heading
         * part of the way at most (measured: 0 and 1.7 of the 4°) */
        prm.impact = BL_PINPOINT_IMPACT_ECHO;
        prm.heading_sigma_rad = (bl_real)0.05;
        bl_pose q = {(bl_real)x, (bl_real)y, (bl_real)(th + sign * 4 * deg)};
        assert_int_equal(bl_pinpoint_correct(&map, &ring, b, n, &prm, &q, &r), BL_OK);
        assert_true(fabs((double)q.theta_rad - th) > 1 * deg);
    }
}

/* The heading's prior (heading_sigma_rad): with noisy specular ranges
 * (σ = max(3 cm, 1 %)) at the true pose, the heading the corrector gives back
 * stays near the odometry's; without the prior (0: the paper's F) the
 * ranges' noise, seen through the ring's 0.2 m lever arm only, turns it
 * several times further. */
static void test_pinpoint_heading_prior(void **state)
{
    (void)state;
    bl_map map;
    bl_sonar_ring ring;
    world_map(&map);
    world_ring(&ring);
    double sum_prior = 0, sum_none = 0;
    int used = 0;
    for (int pass = 0; pass < 2; ++pass) {
        rng_seed(31);
        bl_pinpoint_params prm;
        bl_pinpoint_default(&prm);
        if (pass == 1) prm.heading_sigma_rad = 0;
        for (int k = 0; k < 200; ++k) {
            const double x = 1.5 + 3.0 * rng_uniform(), y = 1.0 + 2.0 * rng_uniform();
            const double th = -3.0 + 6.0 * rng_uniform();
            bl_sonar_range b[8];
            const uint32_t n = burst_of(x, y, th, 1, b);
            for (uint32_t i = 0; i < n; ++i)
                b[i].range_m += (bl_real)(fmax(0.03, 0.01 * (double)b[i].range_m) * rng_gauss());
            bl_pose p = {(bl_real)x, (bl_real)y, (bl_real)th};
            bl_pinpoint_result r;
            assert_int_equal(bl_pinpoint_correct(&map, &ring, b, n, &prm, &p, &r), BL_OK);
            const double dth = fabs(remainder((double)p.theta_rad - th, 6.283185307179586));
            if (pass == 0) {
                sum_prior += dth;
                ++used;
            } else {
                sum_none += dth;
            }
        }
    }
    assert_int_equal(used, 200);
    assert_true(sum_prior / used < 0.01);  /* mean |Δθ| under 0.6° */
    assert_true(sum_none > 3 * sum_prior); /* the prior is what holds it */
}

/* The end-point case (eq. 4): an impact beyond a segment's end costs its
 * squared distance to that end, not to the line (eq. 3). */
static void test_pinpoint_endpoint_case(void **state)
{
    (void)state;
    static const bl_segment seg[1] = {{0, 0, 1, 0}};
    bl_map map = {seg, 1};
    bl_sonar_mount mount = {0, 0, 0};
    bl_sonar_ring ring;
    world_ring(&ring);
    ring.mounts = &mount;
    ring.count = 1;
    ring.unused_mask = 0;
    /* robot at (1.1, 1.05) facing -y (θ = -π/2): the foot (1.1, 0) is off the
     * segment, its end (1, 0) inside the cone at |(0.1, 1.05)| m */
    bl_pose p = {(bl_real)1.1, (bl_real)1.05, (bl_real)(-1.5707963267948966)};
    const bl_sonar_range b = {0, (bl_real)0.9, 0, NULL};
    bl_pinpoint_params prm;
    bl_pinpoint_default(&prm);
    prm.min_matches = 3; /* one impact: evaluated, not corrected */
    bl_pinpoint_result r;
    const bl_pose before = p;
    assert_int_equal(bl_pinpoint_correct(&map, &ring, &b, 1, &prm, &p, &r), BL_OK);
    assert_int_equal(r.matched, 1);
    assert_int_equal(r.outcome, BL_PINPOINT_NONE);
    assert_memory_equal(&p, &before, sizeof p);
    /* eq. 4: a 0.9 m range, the impact on the ray to the end,
     * (0.9 − |(0.1, 1.05)|)² m²; eq. 3 would give (1.05 − 0.9)² = 0.0225 */
    const double h = hypot(0.1, 1.05);
    assert_true(fabs((double)r.cost_before_m2 - (0.9 - h) * (0.9 - h)) < 1e-6);
    /* over the segment (x = 0.9): eq. 3, the perpendicular distance */
    p.x_m = (bl_real)0.9;
    assert_int_equal(bl_pinpoint_correct(&map, &ring, &b, 1, &prm, &p, &r), BL_OK);
    assert_true(fabs((double)r.cost_before_m2 - 0.0225) < 1e-6);
    /* and with one impact allowed to correct, the pose moves it onto the end's
     * circle: the residual is gone, F continuously derivable across eq. 3/4 */
    prm.min_matches = 1;
    p = before;
    assert_int_equal(bl_pinpoint_correct(&map, &ring, &b, 1, &prm, &p, &r), BL_OK);
    assert_int_equal(r.outcome, BL_PINPOINT_CONVERGED);
    assert_true((double)r.cost_after_m2 < 5e-3);
    assert_true((double)r.cost_after_m2 < (double)r.cost_before_m2);
}

/* The stopping rules and the per-axis fall-back (§3.1 steps 6-8), on the
 * paper's impacts (eq. 1 on the axis) and its gradient descent. A corridor:
 * walls y = 0 and y = 4, x = 6 ahead; sensors forward, left and right, 0.2 m
 * from the centre, their ranges exact from (2, 1, 0). From (2.2, 1.1, 0):
 * the forward impact is 0.2 m beyond x = 6, the two side impacts 0.1 m
 * above their walls: F = 0.04 + 2·0.01 = 0.06 m²; ∂F/∂θ = 0 (every impact's
 * dM/dθ runs along its wall). */
static void test_pinpoint_stopping_rules(void **state)
{
    (void)state;
    static const bl_segment seg[3] = {{-10, 0, 10, 0}, {-10, 4, 10, 4}, {6, -10, 6, 10}};
    static const bl_sonar_mount mounts[3] = {
        {(bl_real)0.2, 0, 0}, {0, (bl_real)0.2, (bl_real)1.5707963267948966}, {0, (bl_real)-0.2, (bl_real)-1.5707963267948966}};
    bl_map map = {seg, 3};
    bl_sonar_ring ring;
    world_ring(&ring);
    ring.mounts = mounts;
    ring.count = 3;
    ring.unused_mask = 0;
    const bl_sonar_range b[3] = {{0, (bl_real)3.8, 0, NULL}, {1, (bl_real)2.8, 0, NULL}, {2, (bl_real)0.8, 0, NULL}};
    bl_pinpoint_params prm;
    bl_pinpoint_default(&prm);
    prm.impact = BL_PINPOINT_IMPACT_AXIS;
    prm.heading_sigma_rad = 0; /* the paper's F */
    /* α = 0.25: δ = −α ∂F/∂q = −0.5 Σ r_i J_i takes y (two impacts, J_y = 1
     * each) onto its walls in one step and x (one impact) half-way */
    prm.descent_rate = (bl_real)0.25;
    prm.max_iterations = 1;
    bl_pose p = {(bl_real)2.2, (bl_real)1.1, 0};
    bl_pinpoint_result r;
    assert_int_equal(bl_pinpoint_correct(&map, &ring, b, 3, &prm, &p, &r), BL_OK);
    assert_int_equal(r.matched, 3);
    assert_true(fabs((double)r.cost_before_m2 - 0.06) < 1e-6);
    /* 6-1: after n = N = 1, F = 0.01 m² > ε and ∂F/∂x = 0.2 m > ε': stopped
     * on N. 7: the original pose, except y (∂F/∂y = 0: 7-2) and θ (7-3); x
     * is given back (a global correction would move it to 2.1) */
    assert_int_equal(r.iterations, 1);
    assert_int_equal(r.outcome, BL_PINPOINT_PARTIAL);
    assert_int_equal(r.axes, BL_AXIS_Y | BL_AXIS_THETA);
    assert_true(fabs((double)p.x_m - 2.2) < 1e-5);
    assert_true(fabs((double)p.y_m - 1.0) < 1e-5);
    assert_true(fabs((double)p.theta_rad) < 1e-5);
    /* 8: with N = 10 the descent goes on until F < ε (6-1): its second
     * step (x 10 → 5 cm beyond its wall) is cut at its first point with
     * F < ε: the whole correction, x left at the edge of the paper's
     * deadband, √ε = 7.07 cm beyond its wall */
    prm.max_iterations = 10;
    p = (bl_pose){(bl_real)2.2, (bl_real)1.1, 0};
    assert_int_equal(bl_pinpoint_correct(&map, &ring, b, 3, &prm, &p, &r), BL_OK);
    assert_int_equal(r.outcome, BL_PINPOINT_CONVERGED);
    assert_int_equal(r.axes, BL_AXIS_X | BL_AXIS_Y | BL_AXIS_THETA);
    assert_true((double)r.cost_after_m2 < 5e-3);
    assert_true((double)p.x_m - 2.0 > 0.069 && (double)p.x_m - 2.0 < 0.0708);
    assert_true(fabs((double)p.y_m - 1.0) < 1e-5);
    /* 6-1 at n = 0: F already below ε at the odometric pose (3 cm off in y:
     * F = 1.8e-3 m²): no step, the pose untouched, an error the burst sees
     * left standing */
    p = (bl_pose){2, (bl_real)1.03, 0};
    const bl_pose before = p;
    assert_int_equal(bl_pinpoint_correct(&map, &ring, b, 3, &prm, &p, &r), BL_OK);
    assert_int_equal(r.outcome, BL_PINPOINT_CONVERGED);
    assert_int_equal(r.iterations, 0);
    assert_true(fabs((double)r.cost_before_m2 - 1.8e-3) < 1e-6);
    assert_memory_equal(&p, &before, sizeof p);
}

/* The 25 cm association gate: an impact 24 cm from the only wall is
 * matched, one 26 cm away is not. */
static void test_pinpoint_gate(void **state)
{
    (void)state;
    static const bl_segment seg[1] = {{0, 0, 4, 0}};
    bl_map map = {seg, 1};
    bl_sonar_mount mount = {0, 0, 0};
    bl_sonar_ring ring;
    world_ring(&ring);
    ring.mounts = &mount;
    ring.count = 1;
    ring.unused_mask = 0;
    bl_pinpoint_params prm;
    bl_pinpoint_default(&prm);
    bl_pinpoint_result r;
    const bl_sonar_range b = {0, 1, 0, NULL};
    bl_pose p = {2, (bl_real)1.24, (bl_real)(-1.5707963267948966)}; /* impact at y = 0.24 */
    assert_int_equal(bl_pinpoint_correct(&map, &ring, &b, 1, &prm, &p, &r), BL_OK);
    assert_int_equal(r.matched, 1);
    p.y_m = (bl_real)1.26; /* impact at y = 0.26 */
    assert_int_equal(bl_pinpoint_correct(&map, &ring, &b, 1, &prm, &p, &r), BL_OK);
    assert_int_equal(r.matched, 0);
    assert_true(r.cost_before_m2 == 0);
    /* the gate is the ring's */
    ring.gate_m = (bl_real)0.3;
    assert_int_equal(bl_pinpoint_correct(&map, &ring, &b, 1, &prm, &p, &r), BL_OK);
    assert_int_equal(r.matched, 1);
}

/* Bad data is counted and dropped, by cause; the pose is still corrected
 * from the good ranges. */
static void test_pinpoint_bad_ranges_counted(void **state)
{
    (void)state;
    bl_map map;
    bl_sonar_ring ring;
    world_map(&map);
    world_ring(&ring);
    bl_sonar_range b[14];
    uint32_t n = burst_of(2.5, 2.0, 0.2, 1, b);
    uint32_t no_echo = 0; /* beams through the door */
    for (uint32_t k = 0; k < n; ++k) no_echo += b[k].flags != 0;
    const bl_sonar_range bad[] = {
        {8, 1, 0, NULL},                      /* unknown sensor */
        {4, 1, 0, NULL},                      /* unused (rear) sensor */
        {1, 1, BL_SONAR_NO_ECHO, NULL},       /* flagged */
        {2, 1, BL_SONAR_MAX_RANGE, NULL},     /* flagged */
        {3, (bl_real)NAN, 0, NULL},           /* non-finite */
        {5, (bl_real)0.1, 0, NULL},           /* inside the blanking */
        {6, (bl_real)10.5, 0, NULL},          /* beyond max_range_m */
    };
    memcpy(&b[n], bad, sizeof bad);
    n += 7;
    bl_pose p = {(bl_real)2.55, (bl_real)1.95, (bl_real)0.22};
    bl_pinpoint_result r;
    assert_int_equal(bl_pinpoint_correct(&map, &ring, b, n, NULL, &p, &r), BL_OK);
    assert_int_equal(r.valid, 7 - no_echo);
    assert_int_equal(r.dropped.unknown_sensor, 1);
    assert_int_equal(r.dropped.unused_sensor, 1);
    assert_int_equal(r.dropped.flagged, 2 + no_echo);
    assert_int_equal(r.dropped.non_finite, 1);
    assert_int_equal(r.dropped.out_of_range, 2);
    assert_int_equal(r.outcome, BL_PINPOINT_CONVERGED);
    /* the paper's stop (F < ε = 5e-3 m²): the pose nearer than the odometry's 7 cm
     * (exact specular ranges) */
    assert_true((double)r.cost_after_m2 < 5e-3);
    assert_true(hypot((double)p.x_m - 2.5, (double)p.y_m - 2.0) < 0.8 * hypot(0.05, 0.05));
}

/* Bad input is refused with BL_EINVAL and nothing written. */
static void test_pinpoint_refuses_bad_input(void **state)
{
    (void)state;
    bl_map map;
    bl_sonar_ring ring;
    world_map(&map);
    world_ring(&ring);
    bl_sonar_range b[8];
    const uint32_t n = burst_of(2.5, 2.0, 0.2, 1, b);
    const bl_pose start = {(bl_real)2.55, (bl_real)1.95, (bl_real)0.22};
    bl_pose p = start;
    bl_pinpoint_result r, r0;
    memset(&r, 0x5a, sizeof r);
    r0 = r;
    assert_int_equal(bl_pinpoint_correct(NULL, &ring, b, n, NULL, &p, &r), BL_EINVAL);
    assert_int_equal(bl_pinpoint_correct(&map, NULL, b, n, NULL, &p, &r), BL_EINVAL);
    assert_int_equal(bl_pinpoint_correct(&map, &ring, NULL, n, NULL, &p, &r), BL_EINVAL);
    assert_int_equal(bl_pinpoint_correct(&map, &ring, b, n, NULL, NULL, &r), BL_EINVAL);
    assert_int_equal(bl_pinpoint_correct(&map, &ring, b, BL_SONAR_MAX_SENSORS + 1, NULL, &p, &r), BL_EINVAL);
    p.theta_rad = (bl_real)NAN;
    assert_int_equal(bl_pinpoint_correct(&map, &ring, b, n, NULL, &p, &r), BL_EINVAL);
    assert_true(isnan((double)p.theta_rad));
    p = start;
    /* a zero-length segment: the map is refused, its index named */
    bl_segment segs[WORLD_SEGMENTS];
    memcpy(segs, world_segments, sizeof segs);
    segs[3].x2_m = segs[3].x1_m;
    segs[3].y2_m = segs[3].y1_m;
    bl_map bad_map = {segs, WORLD_SEGMENTS};
    uint32_t idx = 99;
    assert_int_equal(bl_map_check(&bad_map, &idx), BL_EINVAL);
    assert_int_equal(idx, 3);
    assert_int_equal(bl_pinpoint_correct(&bad_map, &ring, b, n, NULL, &p, &r), BL_EINVAL);
    memcpy(segs, world_segments, sizeof segs);
    segs[1].y2_m = (bl_real)INFINITY;
    assert_int_equal(bl_map_check(&bad_map, &idx), BL_EINVAL);
    assert_int_equal(idx, 1);
    bl_map null_map = {NULL, 2};
    assert_int_equal(bl_map_check(&null_map, NULL), BL_EINVAL);
    bl_map big_map = {world_segments, BL_MAP_MAX_SEGMENTS + 1};
    assert_int_equal(bl_map_check(&big_map, NULL), BL_EINVAL);
    /* a bad ring */
    bl_sonar_ring bad_ring = ring;
    bad_ring.max_range_m = bad_ring.min_range_m;
    assert_int_equal(bl_pinpoint_correct(&map, &bad_ring, b, n, NULL, &p, &r), BL_EINVAL);
    bad_ring = ring;
    bad_ring.count = 0;
    assert_int_equal(bl_sonar_ring_check(&bad_ring, NULL), BL_EINVAL);
    bad_ring = ring;
    bad_ring.beam_width_rad = 0;
    assert_int_equal(bl_sonar_ring_check(&bad_ring, NULL), BL_EINVAL);
    bl_sonar_mount mounts[WORLD_SENSORS];
    memcpy(mounts, world_mounts, sizeof mounts);
    mounts[6].angle_rad = (bl_real)NAN;
    bad_ring = ring;
    bad_ring.mounts = mounts;
    assert_int_equal(bl_sonar_ring_check(&bad_ring, &idx), BL_EINVAL);
    assert_int_equal(idx, 6);
    /* bad parameters */
    bl_pinpoint_params prm;
    bl_pinpoint_default(&prm);
    prm.max_iterations = 0;
    assert_int_equal(bl_pinpoint_correct(&map, &ring, b, n, &prm, &p, &r), BL_EINVAL);
    bl_pinpoint_default(&prm);
    prm.epsilon_grad = (bl_real)NAN;
    assert_int_equal(bl_pinpoint_correct(&map, &ring, b, n, &prm, &p, &r), BL_EINVAL);
    bl_pinpoint_default(&prm);
    prm.heading_sigma_rad = (bl_real)-0.01;
    assert_int_equal(bl_pinpoint_correct(&map, &ring, b, n, &prm, &p, &r), BL_EINVAL);
    bl_pinpoint_default(&prm);
    prm.impact = 2; /* neither ECHO nor AXIS */
    assert_int_equal(bl_pinpoint_correct(&map, &ring, b, n, &prm, &p, &r), BL_EINVAL);
    bl_pinpoint_default(&prm);
    prm.descent_rate = (bl_real)-0.1;
    assert_int_equal(bl_pinpoint_correct(&map, &ring, b, n, &prm, &p, &r), BL_EINVAL);
    prm.descent_rate = (bl_real)NAN;
    assert_int_equal(bl_pinpoint_correct(&map, &ring, b, n, &prm, &p, &r), BL_EINVAL);
    /* nothing written by any of them */
    assert_memory_equal(&p, &start, sizeof p);
    assert_memory_equal(&r, &r0, sizeof r);
    assert_int_equal(bl_map_check(&map, NULL), BL_OK);
    assert_int_equal(bl_sonar_ring_check(&ring, NULL), BL_OK);
}

/* ---- the memory corrector ---- */

/* Ten bursts of specular ranges along a straight line at 40° towards the
 * room's top-right corner (v = 0.2 m/s, a burst every 0.5 s): the -30°
 * sensor (axis 10°) hears the right wall at normal incidence, the 60° one
 * (axis 100°) the top wall, their feet moving 0.6-0.8 m along them.
 * Odometry exact, the current estimate off by (dx, dy, dθ): the heading
 * comes back from the fitted walls' orientations, then the position from
 * their midpoints. */
/* When set, the -30° sensor's ranges alternate 15 cm long and short: a
 * scatter inside the 25 cm gate (phantoms, an obstacle beside the wall). */
static int g_scatter_bottom = 0;

static uint32_t drive_arc(bl_memory_corrector *m, const bl_sonar_ring *ring, double *x, double *y, double *th)
{
    uint32_t valid = 0; /* ranges with an echo */
    double px = 3.8, py = 1.5, pth = 0.7;
    for (int k = 0; k < 10; ++k) {
        if (k > 0) {
            const double dth = 0, ds = 0.2 * 0.5;
            px += ds * cos(pth + 0.5 * dth);
            py += ds * sin(pth + 0.5 * dth);
            pth += dth;
        }
        bl_sonar_range b[8];
        const uint32_t n = burst_of(px, py, pth, 1, b);
        for (uint32_t i = 0; i < n; ++i) {
            valid += b[i].flags == 0;
            if (g_scatter_bottom && b[i].sensor == 7) b[i].range_m += (bl_real)(k % 2 ? 0.15 : -0.15);
        }
        /* odometry in its own frame: here the site frame shifted by (10, -3) */
        const bl_pose odo = {(bl_real)(px + 10), (bl_real)(py - 3), (bl_real)pth};
        assert_int_equal(bl_memory_push(m, ring, &odo, b, n), BL_OK);
    }
    *x = px;
    *y = py;
    *th = pth;
    return valid;
}

/* The memory tests' fixture: the room's map and ring, a corrector with the
 * default parameters and the ten bursts of drive_arc, and the true pose at
 * the newest burst. */
struct memory_world {
    bl_map map;
    bl_sonar_ring ring;
    bl_memory_corrector m;
    double x, y, th; /* true pose at the newest burst (m, m, rad) */
    uint32_t valid;  /* ranges with an echo pushed */
};
static struct memory_world g_memory_world;

static int memory_world_setup(void **state)
{
    struct memory_world *w = &g_memory_world;
    memset(w, 0, sizeof *w);
    world_map(&w->map);
    world_ring(&w->ring);
    if (bl_memory_init(&w->m, NULL) != BL_OK) return -1;
    w->valid = drive_arc(&w->m, &w->ring, &w->x, &w->y, &w->th);
    *state = w;
    return 0;
}

/* The same with the -30° sensor's ranges scattered (g_scatter_bottom). */
static int memory_world_setup_scattered(void **state)
{
    g_scatter_bottom = 1;
    const int rc = memory_world_setup(state);
    g_scatter_bottom = 0;
    return rc;
}

static void test_memory_recovers_offset(void **state)
{
    struct memory_world *w = *state;
    const bl_map map = w->map;
    const bl_sonar_ring ring = w->ring;
    const double x = w->x, y = w->y, th = w->th;
    const uint32_t valid = w->valid;
    bl_pose p = {(bl_real)(x + 0.10), (bl_real)(y - 0.08), (bl_real)(th + 0.05)};
    bl_memory_result r;
    assert_int_equal(bl_memory_correct(&w->m, &map, &ring, &p, &r), BL_OK);
    assert_int_equal(r.points, valid);
    assert_true(valid >= 2 * 10); /* at least the two walls' echoes of each burst */
    /* the right and top walls are fitted, from impacts placed at their
     * perpendicular feet (on the beam axes, 10° off the normals, the
     * traces would tilt by ~0.2 rad as the ranges shrink) */
    assert_int_equal(r.segments, 2);
    assert_true(r.matched >= 3 * 3);
    assert_int_equal(r.outcome, BL_PINPOINT_CONVERGED);
    assert_int_equal(r.axes, BL_AXIS_X | BL_AXIS_Y | BL_AXIS_THETA);
    /* heading to a few mrad, then the position to about a centimetre (the
     * fitted midpoints sit on the known walls) */
    assert_true(fabs((double)p.theta_rad - th) < 0.005);
    assert_true(fabs((double)p.x_m - x) < 0.02);
    assert_true(fabs((double)p.y_m - y) < 0.02);
    assert_true(fabs((double)r.dtheta_rad + 0.05) < 0.005);
}

/* A small position offset (3 cm, 4 cm: F of the two fitted midpoints below
 * the paper's ε = 5e-3 m²) is corrected too: the position step stops at
 * its own ε (bl_memory_default: 1e-4 m²), not at the ranges' (which left
 * every offset up to 7 cm standing while the odometry drifted). */
static void test_memory_corrects_small_offset(void **state)
{
    const struct memory_world *w = *state;
    const double x = w->x, y = w->y;
    bl_pose p = {(bl_real)(x + 0.03), (bl_real)(y - 0.04), (bl_real)w->th};
    bl_memory_result r;
    assert_int_equal(bl_memory_correct(&w->m, &w->map, &w->ring, &p, &r), BL_OK);
    assert_int_equal(r.outcome, BL_PINPOINT_CONVERGED);
    assert_true(r.iterations >= 1);
    assert_true(hypot((double)p.x_m - x, (double)p.y_m - y) < 0.01);
}

/* A wall whose impacts scatter (±15 cm, inside the 25 cm gate) gives no
 * fit (Crowley's alignment test): the heading still comes from the right
 * wall alone, and y (observed only by the bottom wall's fit) is left. */
static void test_memory_scattered_fit_refused(void **state)
{
    const struct memory_world *w = *state; /* memory_world_setup_scattered */
    const double x = w->x, y = w->y, th = w->th;
    bl_pose p = {(bl_real)(x + 0.10), (bl_real)(y - 0.08), (bl_real)(th + 0.05)};
    bl_memory_result r;
    assert_int_equal(bl_memory_correct(&w->m, &w->map, &w->ring, &p, &r), BL_OK);
    assert_int_equal(r.segments, 1);
    assert_true(fabs((double)p.theta_rad - th) < 0.005);
    assert_true(fabs((double)p.y_m - y) < 0.02);
    assert_true(fabs((double)p.x_m - (x + 0.10)) < 0.01); /* unobserved: not moved */
}

/* The 20° incidence gate: with it at 1° only the shots within 1° of a
 * wall's normal are matched (fewer), and the memory is not changed by a
 * correction (the same correction twice gives the same pose). */
static void test_memory_incidence_gate(void **state)
{
    struct memory_world *w = *state;
    const bl_map map = w->map;
    const bl_sonar_ring ring = w->ring;
    const bl_memory_corrector m = w->m;
    double x = w->x, y = w->y, th = w->th;
    const bl_pose p0 = {(bl_real)(x + 0.05), (bl_real)y, (bl_real)th};
    bl_pose p = p0;
    bl_memory_result r20, r1;
    assert_int_equal(bl_memory_correct(&m, &map, &ring, &p, &r20), BL_OK);
    bl_pose q = p0;
    bl_memory_result again;
    assert_int_equal(bl_memory_correct(&m, &map, &ring, &q, &again), BL_OK);
    assert_memory_equal(&p, &q, sizeof p);
    /* at 40° the right and top walls' normals are 10° off the -30° and 60°
     * sensors' axes: at a 1° gate none of their shots is matched */
    bl_memory_params prm;
    bl_memory_default(&prm);
    prm.incidence_gate_rad = (bl_real)(1.0 * 3.141592653589793 / 180.0);
    bl_memory_corrector m1;
    assert_int_equal(bl_memory_init(&m1, &prm), BL_OK);
    drive_arc(&m1, &ring, &x, &y, &th);
    p = p0;
    assert_int_equal(bl_memory_correct(&m1, &map, &ring, &p, &r1), BL_OK);
    assert_true(r1.matched < r20.matched / 3);
    /* the gate's count at 20°: those two sensors' shots, 2 per burst (the
     * others hear corners or nothing: no wall's normal within 20°) */
    assert_int_equal(r20.matched, 20);
    assert_int_equal(r1.matched, 0);
}

/* Bad input refused, the corrector byte-identical; bad ranges counted. */
static void test_memory_refuses_bad_input(void **state)
{
    struct memory_world *w = *state;
    const bl_map map = w->map;
    const bl_sonar_ring ring = w->ring;
    bl_memory_corrector m;
    memset(&m, 0, sizeof m);
    bl_pose origin = {0, 0, 0};
    assert_int_equal(bl_memory_correct(&m, &map, &ring, &origin, NULL), BL_ENOTINIT);
    assert_int_equal(bl_memory_init(NULL, NULL), BL_EINVAL);
    bl_memory_params prm;
    bl_memory_default(&prm);
    prm.depth = BL_MEMORY_MAX_BURSTS + 1;
    memset(&m, 0, sizeof m);
    assert_int_equal(bl_memory_init(&m, &prm), BL_EINVAL);
    assert_int_equal(bl_memory_push(&m, &ring, &(bl_pose){0, 0, 0}, NULL, 0), BL_ENOTINIT);
    m = w->m; /* the fixture's, initialised and driven */
    bl_memory_corrector copy;
    memcpy(&copy, &m, sizeof m);
    bl_sonar_range b[8];
    const uint32_t n = burst_of(1.8, 2, -0.3, 0, b); /* every beam on a wall */
    for (uint32_t k = 0; k < n; ++k) assert_int_equal(b[k].flags, 0);
    const bl_pose good = {(bl_real)1.8, 2, (bl_real)-0.3};
    const bl_pose nan_pose = {(bl_real)NAN, 2, 0};
    assert_int_equal(bl_memory_push(NULL, &ring, &good, b, n), BL_EINVAL);
    assert_int_equal(bl_memory_push(&m, NULL, &good, b, n), BL_EINVAL);
    assert_int_equal(bl_memory_push(&m, &ring, NULL, b, n), BL_EINVAL);
    assert_int_equal(bl_memory_push(&m, &ring, &good, NULL, n), BL_EINVAL);
    assert_int_equal(bl_memory_push(&m, &ring, &nan_pose, b, n), BL_EINVAL);
    assert_int_equal(bl_memory_push(&m, &ring, &good, b, BL_SONAR_MAX_SENSORS + 1), BL_EINVAL);
    bl_pose p = nan_pose;
    assert_int_equal(bl_memory_correct(&m, &map, &ring, &p, NULL), BL_EINVAL);
    p = good;
    bl_segment segs[WORLD_SEGMENTS];
    memcpy(segs, world_segments, sizeof segs);
    segs[0].x1_m = (bl_real)NAN;
    const bl_map bad_map = {segs, WORLD_SEGMENTS};
    assert_int_equal(bl_memory_correct(&m, &bad_map, &ring, &p, NULL), BL_EINVAL);
    assert_int_equal(bl_memory_correct(&m, NULL, &ring, &p, NULL), BL_EINVAL);
    assert_memory_equal(&m, &copy, sizeof m);
    assert_memory_equal(&p, &good, sizeof p);
    /* bad data: counted at the push, cumulative */
    bl_memory_result r;
    assert_int_equal(bl_memory_correct(&m, &map, &ring, &p, &r), BL_OK);
    const uint32_t flagged0 = r.dropped.flagged, last_points = r.points;
    b[0].flags = BL_SONAR_NO_ECHO;
    b[1].sensor = 12;
    b[2].range_m = (bl_real)NAN;
    assert_int_equal(bl_memory_push(&m, &ring, &good, b, n), BL_OK);
    assert_int_equal(bl_memory_correct(&m, &map, &ring, &p, &r), BL_OK);
    assert_int_equal(r.dropped.flagged, flagged0 + 1);
    assert_int_equal(r.dropped.unknown_sensor, 1);
    assert_int_equal(r.dropped.non_finite, 1);
    /* the oldest burst (<= 7 ranges) went, the new one brought its good ones */
    const uint32_t added = n - 3;
    assert_true(r.points <= last_points + added && r.points + 7 >= last_points + added);
}

/* The dead-reckoning step: a turn in place and a straight run. */
static void test_odometry_step(void **state)
{
    (void)state;
    bl_pose p = {1, 2, 0};
    assert_int_equal(bl_pose_odometry_step(&p, (bl_real)-0.25 * (bl_real)3.141592653589793,
                                           (bl_real)0.25 * (bl_real)3.141592653589793, 1),
                     BL_OK);
    assert_true(fabs((double)p.theta_rad - 1.5707963267948966) < 1e-6);
    assert_true(fabs((double)p.x_m - 1) < 1e-6 && fabs((double)p.y_m - 2) < 1e-6);
    assert_int_equal(bl_pose_odometry_step(&p, 1, 1, 1), BL_OK);
    assert_true(fabs((double)p.x_m - 1) < 1e-6 && fabs((double)p.y_m - 3) < 1e-6);
    const bl_pose before = p;
    assert_int_equal(bl_pose_odometry_step(&p, 1, 1, 0), BL_EINVAL);
    assert_int_equal(bl_pose_odometry_step(&p, (bl_real)NAN, 1, 1), BL_EINVAL);
    assert_memory_equal(&p, &before, sizeof p);
}

int main(void)
{
    (void)rng_gauss; /* test_rng.h: only the uniform draws here */
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_pinpoint_recovers_offset),
        cmocka_unit_test(test_pinpoint_specular_true_pose_is_kept),
        cmocka_unit_test(test_pinpoint_axis_observes_heading),
        cmocka_unit_test(test_pinpoint_heading_prior),  cmocka_unit_test(test_pinpoint_endpoint_case),
        cmocka_unit_test(test_pinpoint_stopping_rules), cmocka_unit_test(test_pinpoint_gate),             cmocka_unit_test(test_pinpoint_bad_ranges_counted),
        cmocka_unit_test(test_pinpoint_refuses_bad_input),
        cmocka_unit_test_setup(test_memory_recovers_offset, memory_world_setup),
        cmocka_unit_test_setup(test_memory_corrects_small_offset, memory_world_setup),
        cmocka_unit_test_setup(test_memory_scattered_fit_refused, memory_world_setup_scattered),
        cmocka_unit_test_setup(test_memory_incidence_gate, memory_world_setup),
        cmocka_unit_test_setup(test_memory_refuses_bad_input, memory_world_setup),
        cmocka_unit_test(test_odometry_step),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
