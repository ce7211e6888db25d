/* Unit tests of cull/'s frustum, view and cell enumeration. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "cull/cull.h"
#include "tests/check.h"
#include "tiles/tiles-internal.h"

static struct tw_box box(float x0, float y0, float z0, float x1, float y1, float z1)
{
    struct tw_box b = {{x0, y0, z0}, {x1, y1, z1}};
    return b;
}

/* A camera at the origin looking along +z (yaw 0), 90 degrees vertical fov,
 * square aspect, near 1, far 100: the frustum is |x| <= z, |y| <= z. */
static void test_frustum_known_cases(void)
{
    struct tw_view v;
    const float eye[3] = {0, 0, 0};
    tw_cull_view_setup(&v, (struct tw_cell){0, 0}, eye, 0.0f, 0.0f, 90.0f, 1.0f, 1.0f, 100.0f);
    const struct tw_frustum *f = &v.frustum;
    struct tw_box b;
    b = box(-1, -1, 10, 1, 1, 12);
    CHECK(tw_cull_frustum_box(f, &b, NULL) == TW_CULL_INSIDE);
    b = box(-1, -1, -12, 1, 1, -10);           /* behind */
    CHECK(tw_cull_frustum_box(f, &b, NULL) == TW_CULL_OUTSIDE);
    b = box(20, -1, 10, 22, 1, 12);            /* right of |x| <= z */
    CHECK(tw_cull_frustum_box(f, &b, NULL) == TW_CULL_OUTSIDE);
    b = box(8, -1, 10, 12, 1, 12);             /* straddles the side plane */
    CHECK(tw_cull_frustum_box(f, &b, NULL) == TW_CULL_INTERSECT);
    b = box(-1, -1, 150, 1, 1, 160);           /* beyond far */
    CHECK(tw_cull_frustum_box(f, &b, NULL) == TW_CULL_OUTSIDE);
    b = box(-1, -1, 0.2f, 1, 1, 0.5f);         /* before near */
    CHECK(tw_cull_frustum_box(f, &b, NULL) == TW_CULL_OUTSIDE);
    b = box(-1, -1, -1, 1, 1, 1);              /* holds the eye: cut by near */
    CHECK(tw_cull_frustum_box(f, &b, NULL) == TW_CULL_INTERSECT);
    /* The offset moves the box. */
    b = box(-1, -1, -12, 1, 1, -10);
    CHECK(tw_cull_frustum_box(f, &b, (const float[3]){0, 0, 22}) == TW_CULL_INSIDE);

    /* Yaw 90 looks along +x. */
    tw_cull_view_setup(&v, (struct tw_cell){0, 0}, eye, 90.0f, 0.0f, 90.0f, 1.0f, 1.0f, 100.0f);
    b = box(10, -1, -1, 12, 1, 1);
    CHECK(tw_cull_frustum_box(&v.frustum, &b, NULL) == TW_CULL_INSIDE);
    b = box(-1, -1, 10, 1, 1, 12);
    CHECK(tw_cull_frustum_box(&v.frustum, &b, NULL) == TW_CULL_OUTSIDE);
    /* Pitch 45 up: a box straight up-ahead is inside, one down-ahead is not. */
    tw_cull_view_setup(&v, (struct tw_cell){0, 0}, eye, 0.0f, 45.0f, 60.0f, 1.0f, 1.0f, 100.0f);
    b = box(-1, 9, 9, 1, 11, 11);
    CHECK(tw_cull_frustum_box(&v.frustum, &b, NULL) == TW_CULL_INSIDE);
    b = box(-1, -11, 9, 1, -9, 11);
    CHECK(tw_cull_frustum_box(&v.frustum, &b, NULL) == TW_CULL_OUTSIDE);
}

static void test_near_rule(void)
{
    struct tw_view v;
    const float eye[3] = {5, 1.7f, 5};
    tw_cull_view_setup(&v, (struct tw_cell){0, 0}, eye, 0.0f, 0.0f, 60.0f, 16.0f / 9.0f, 0.2f, 500.0f);
    struct tw_box b = box(0, 0, 0, 10, 10, 10);
    CHECK(tw_cull_near_box(&v, &b, NULL));                          /* holds the eye */
    b = box(5.1f, 0, 5.1f, 6, 2, 6);
    CHECK(tw_cull_near_box(&v, &b, NULL));                          /* within near reach */
    b = box(0, 0, 8, 10, 10, 10);
    CHECK(!tw_cull_near_box(&v, &b, NULL));                         /* 3 m ahead */
    CHECK(fabsf(tw_cull_box_distance(&v, &b, NULL) - 3.0f) < 1e-5f);
    CHECK(v.near_radius > 0.2f && v.near_radius < 0.5f);
}

/* The screen rectangle of a box, as a fraction of the image: the camera of
 * test_frustum_known_cases sees |x| <= z, |y| <= z. */
static void test_screen_fraction(void)
{
    struct tw_view v;
    const float eye[3] = {0, 0, 0};
    tw_cull_view_setup(&v, (struct tw_cell){0, 0}, eye, 0.0f, 0.0f, 90.0f, 1.0f, 1.0f, 100.0f);
    /* A flat square of side 10 at z = 10: half the image each way. */
    struct tw_box b = box(-5, -5, 10, 5, 5, 10);
    CHECK(fabsf(tw_cull_box_screen_fraction(&v, &b, NULL) - 0.25f) < 1e-4f);
    /* Its depth adds nothing beyond its near face's rectangle. */
    b = box(-5, -5, 10, 5, 5, 30);
    CHECK(fabsf(tw_cull_box_screen_fraction(&v, &b, NULL) - 0.25f) < 1e-4f);
    /* Off to one side: the part on screen only (a quarter of the width,
     * half the height). */
    b = box(5, -5, 10, 15, 5, 10);
    CHECK(fabsf(tw_cull_box_screen_fraction(&v, &b, NULL) - 0.125f) < 1e-4f);
    /* Wholly off screen, covering nothing; larger than the image: all. */
    b = box(15, -5, 10, 25, 5, 10);
    CHECK(tw_cull_box_screen_fraction(&v, &b, NULL) == 0.0f);
    b = box(-50, -50, 10, 50, 50, 12);
    CHECK(tw_cull_box_screen_fraction(&v, &b, NULL) == 1.0f);
    /* Reaching behind the eye: all, the bound a query cannot exceed. */
    b = box(-1, -1, -1, 1, 1, 5);
    CHECK(tw_cull_box_screen_fraction(&v, &b, NULL) == 1.0f);
    /* The offset moves the box: the square twice as far covers a quarter. */
    b = box(-5, -5, 10, 5, 5, 10);
    CHECK(fabsf(tw_cull_box_screen_fraction(&v, &b, (const float[3]){0, 0, 10}) - 0.0625f) <
          1e-4f);
}

/* Cells come front to back, all within the view distance and the frustum,
 * and none is missing: compared with a brute-force scan. */
static void test_cells_in_view(void)
{
    struct tw_view v;
    const float eye[3] = {3, 1.7f, 40};
    const struct tw_cell cam = {(int64_t)1 << 40, -((int64_t)1 << 40)};
    tw_cull_view_setup(&v, cam, eye, 30.0f, -5.0f, 60.0f, 16.0f / 9.0f, 0.2f, 900.0f);
    v.view_distance = 400.0f;
    const struct tw_box common = box(0, 0, 0, 80, 60, 80);
    static struct tw_cull_cell cells[4096];
    const size_t n = tw_cull_cells_in_view(&v, &common, 80, 80, cells, 4096);
    CHECK(n > 10 && n < 4096);
    size_t brute = 0;
    for (int64_t di = -20; di <= 20; di++)
        for (int64_t dj = -20; dj <= 20; dj++) {
            const float off[3] = {di * 80.0f, 0, dj * 80.0f};
            if (tw_cull_box_distance(&v, &common, off) <= 400.0f &&
                tw_cull_frustum_box(&v.frustum, &common, off) != TW_CULL_OUTSIDE)
                brute++;
        }
    CHECK(n == brute);
    CHECK(cells[0].cell.i == cam.i && cells[0].cell.j == cam.j && cells[0].distance == 0.0f);
    for (size_t k = 1; k < n && k < 4096; k++) {
        CHECK(cells[k].distance >= cells[k - 1].distance);
        CHECK(cells[k].distance <= 400.0f);
    }
    /* Too little room: the count is still returned, nothing overruns. */
    struct tw_cull_cell few[4];
    CHECK(tw_cull_cells_in_view(&v, &common, 80, 80, few, 4) == n);
}

/* Issue 11, class 2 and 3: the scan of one frame costs at most
 * TW_TILES_MAX_CELLS_IN_VIEW box tests whatever the footprint, the common
 * box and the view distance, says when it stopped short, keeps the cells
 * nearest the camera, and never converts an out-of-range float to an
 * integer nor hands qsort() a NULL array. */
static void test_cells_in_view_bounded(void)
{
    struct tw_view v;
    const float eye[3] = {0.004f, 1.7f, 0.005f};
    tw_cull_view_setup(&v, (struct tw_cell){-5, 7}, eye, 10.0f, 0.0f, 60.0f, 16.0f / 9.0f,
                       0.2f, 700.0f);
    v.view_distance = 600.0f;

    /* 1 cm tiles: 1.4e10 cells within 600 m. */
    struct tw_box tiny = box(0, 0, 0, 0.01f, 2, 0.01f);
    static struct tw_cull_cell cells[TW_TILES_MAX_CELLS_IN_VIEW];
    struct tw_cull_scan scan = {0, false};
    size_t n = tw_cull_cells_in_view_scan(&v, &tiny, 0.01f, 0.01f, cells,
                                          TW_TILES_MAX_CELLS_IN_VIEW, &scan);
    CHECK(scan.truncated);
    CHECK(scan.cells_tested > 0 && scan.cells_tested <= TW_TILES_MAX_CELLS_IN_VIEW);
    CHECK(n > 0 && n <= scan.cells_tested);
    CHECK(tw_tiles_cells_in_reach(&tiny, 0.01f, 0.01f, 600.0f) > 1e10);
    /* The nearest cells are kept (those just beyond the near plane), sorted. */
    CHECK(cells[0].distance < 0.25f);
    for (size_t k = 0; k < n; k++)
        CHECK(cells[k].distance <= 2.0f && (k == 0 || cells[k].distance >= cells[k - 1].distance));

    /* A common box a million metres wide on 80 m tiles (a manifest scale of
     * 10^6): every cell's box reaches the camera. */
    struct tw_box huge = box(-5e5f, 0, -5e5f, 5e5f, 10, 5e5f);
    n = tw_cull_cells_in_view_scan(&v, &huge, 80, 80, cells, TW_TILES_MAX_CELLS_IN_VIEW, &scan);
    CHECK(scan.truncated && scan.cells_tested <= TW_TILES_MAX_CELLS_IN_VIEW);
    CHECK(n > 0 && n <= TW_TILES_MAX_CELLS_IN_VIEW);

    /* A long thin range is cut along its long axis only. */
    struct tw_box strip = box(0, 0, 0, 80, 10, 1e5f);
    n = tw_cull_cells_in_view_scan(&v, &strip, 80, 1, cells, TW_TILES_MAX_CELLS_IN_VIEW, &scan);
    CHECK(scan.truncated && scan.cells_tested <= TW_TILES_MAX_CELLS_IN_VIEW);
    CHECK(scan.cells_tested >= TW_TILES_MAX_CELLS_IN_VIEW / 2);

    /* A footprint of 1e-30 and a camera far below the ground: no integer
     * overflow, no qsort(NULL, 0). */
    n = tw_cull_cells_in_view_scan(&v, &tiny, 1e-30f, 1e-30f, NULL, 0, &scan);
    CHECK(scan.cells_tested <= TW_TILES_MAX_CELLS_IN_VIEW);
    const float deep[3] = {3, -1e30f, 3};
    tw_cull_view_setup(&v, (struct tw_cell){0, 0}, deep, 0.0f, 0.0f, 60.0f, 1.0f, 0.2f, 700.0f);
    v.view_distance = 600.0f;
    const struct tw_box common = box(0, 0, 0, 80, 60, 80);
    n = tw_cull_cells_in_view_scan(&v, &common, 80, 80, NULL, 0, &scan);
    CHECK(n == 0 && !scan.truncated);
    n = tw_cull_cells_in_view(&v, &common, 80, 80, NULL, 0);
    CHECK(n == 0);
    /* Nothing finite to scan: no cells, no work. */
    const float lost[3] = {NAN, 0, 0};
    tw_cull_view_setup(&v, (struct tw_cell){0, 0}, lost, 0.0f, 0.0f, 60.0f, 1.0f, 0.2f, 700.0f);
    v.view_distance = 600.0f;
    CHECK(tw_cull_cells_in_view_scan(&v, &common, 80, 80, cells, 16, &scan) == 0 &&
          scan.cells_tested == 0);
    v.view_distance = INFINITY;
    CHECK(tw_cull_cells_in_view_scan(&v, &common, 80, 80, cells, 16, &scan) == 0);
    CHECK(tw_cull_cells_in_view_scan(&v, &common, INFINITY, 80, cells, 16, &scan) == 0);
}

int main(void)
{
    test_frustum_known_cases();
    test_near_rule();
    test_screen_fraction();
    test_cells_in_view();
    test_cells_in_view_bounded();
    return check_summary("test-cull");
}
