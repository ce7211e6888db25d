/* Frusta, the view, cell enumeration and per-tile frustum culling (cull.h). */
#include "cull/cull-private.h"
#include "tiles/tiles-internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void tw_cull_frustum_from_matrix(const float m[16], struct tw_frustum *out)
{
    /* Row r of a column-major matrix is (m[r], m[4 + r], m[8 + r], m[12 + r]). */
    static const int rows[6] = {0, 0, 1, 1, 2, 2};
    static const float signs[6] = {1, -1, 1, -1, 1, -1};
    for (int p = 0; p < 6; p++) {
        const int r = rows[p];
        const float s = signs[p];
        float a = m[3] + s * m[r], b = m[7] + s * m[4 + r];
        float c = m[11] + s * m[8 + r], d = m[15] + s * m[12 + r];
        const float len = sqrtf(a * a + b * b + c * c);
        if (len > 0.0f) {
            a /= len; b /= len; c /= len; d /= len;
        }
        out->planes[p] = (struct tw_plane){{a, b, c}, d};
    }
}

enum tw_cull_test tw_cull_frustum_box(const struct tw_frustum *f, const struct tw_box *b,
                                      const float offset[3])
{
    const float o[3] = {offset ? offset[0] : 0.0f, offset ? offset[1] : 0.0f,
                        offset ? offset[2] : 0.0f};
    enum tw_cull_test result = TW_CULL_INSIDE;
    for (int p = 0; p < 6; p++) {
        const struct tw_plane *pl = &f->planes[p];
        float far_d = pl->d, near_d = pl->d;
        for (int k = 0; k < 3; k++) {
            const float lo = b->min[k] + o[k], hi = b->max[k] + o[k];
            far_d += pl->n[k] * (pl->n[k] >= 0.0f ? hi : lo);
            near_d += pl->n[k] * (pl->n[k] >= 0.0f ? lo : hi);
        }
        if (far_d < 0.0f)
            return TW_CULL_OUTSIDE;
        if (near_d < 0.0f)
            result = TW_CULL_INTERSECT;
    }
    return result;
}

static void mat4_mul(const float a[16], const float b[16], float out[16])
{
    for (int c = 0; c < 4; c++)
        for (int r = 0; r < 4; r++) {
            float s = 0.0f;
            for (int k = 0; k < 4; k++)
                s += a[4 * k + r] * b[4 * c + k];
            out[4 * c + r] = s;
        }
}

void tw_cull_view_setup(struct tw_view *v, struct tw_cell cell, const float eye[3],
                        float yaw_deg, float pitch_deg, float fov_y_deg, float aspect,
                        float near_plane, float far_plane)
{
    const double to_rad = 3.14159265358979323846 / 180.0;
    const double yaw = yaw_deg * to_rad, pitch = pitch_deg * to_rad;
    /* Yaw 0 looks along +z, yaw 90 along +x; pitch > 0 looks up (DESIGN §9). */
    const float f[3] = {(float)(sin(yaw) * cos(pitch)), (float)sin(pitch),
                        (float)(cos(yaw) * cos(pitch))};
    /* right = f x up with up = +y; well defined while |pitch| < 90. */
    float r[3] = {-f[2], 0.0f, f[0]};
    const float rl = sqrtf(r[0] * r[0] + r[2] * r[2]);
    if (rl > 1e-6f) {
        r[0] /= rl;
        r[2] /= rl;
    } else {
        r[0] = -(float)cos(yaw);
        r[2] = (float)sin(yaw);
    }
    const float u[3] = {r[1] * f[2] - r[2] * f[1], r[2] * f[0] - r[0] * f[2],
                        r[0] * f[1] - r[1] * f[0]};
    const float view[16] = {
        r[0], u[0], -f[0], 0.0f,
        r[1], u[1], -f[1], 0.0f,
        r[2], u[2], -f[2], 0.0f,
        -(r[0] * eye[0] + r[1] * eye[1] + r[2] * eye[2]),
        -(u[0] * eye[0] + u[1] * eye[1] + u[2] * eye[2]),
        f[0] * eye[0] + f[1] * eye[1] + f[2] * eye[2],
        1.0f,
    };
    const float t = 1.0f / (float)tan(0.5 * fov_y_deg * to_rad);
    const float n = near_plane, fa = far_plane;
    const float proj[16] = {
        t / aspect, 0, 0, 0,
        0, t, 0, 0,
        0, 0, (fa + n) / (n - fa), -1,
        0, 0, 2 * fa * n / (n - fa), 0,
    };
    /* Reversed depth: near -> 1, far -> 0. With a float depth buffer the
     * precision is then nearly uniform in relative terms, so surfaces a few
     * centimetres apart far away still resolve, whatever the draw order. */
    const float proj_rz[16] = {
        t / aspect, 0, 0, 0,
        0, t, 0, 0,
        0, 0, n / (fa - n), -1,
        0, 0, fa * n / (fa - n), 0,
    };
    v->cell = cell;
    memcpy(v->eye, eye, sizeof(v->eye));
    memcpy(v->view, view, sizeof(v->view));
    memcpy(v->proj, proj, sizeof(v->proj));
    memcpy(v->proj_rz, proj_rz, sizeof(v->proj_rz));
    mat4_mul(proj, view, v->view_proj);
    mat4_mul(proj_rz, view, v->view_proj_rz);
    tw_cull_frustum_from_matrix(v->view_proj, &v->frustum);
    v->near_plane = near_plane;
    v->far_plane = far_plane;
    /* The near plane's corners lie up to n * sqrt(1 + tx^2 + ty^2) from the
     * eye; keep that radius for the near-plane rule. */
    const float ty = 1.0f / t, tx = ty * aspect;
    v->near_radius = n * sqrtf(1.0f + tx * tx + ty * ty);
}

struct tw_box tw_cull_query_box(const float eye[3], const struct tw_box *b, const float offset[3])
{
    struct tw_box q;
    float d2 = 0.0f;
    for (int a = 0; a < 3; a++) {
        q.min[a] = b->min[a] + (offset ? offset[a] : 0.0f);
        q.max[a] = b->max[a] + (offset ? offset[a] : 0.0f);
        const float e = eye[a] < q.min[a] ? q.min[a] - eye[a]
                                          : (eye[a] > q.max[a] ? eye[a] - q.max[a] : 0.0f);
        d2 += e * e;
    }
    const float margin = TW_CULL_QUERY_MARGIN_M + TW_CULL_QUERY_MARGIN_PER_M * sqrtf(d2);
    for (int a = 0; a < 3; a++) {
        q.min[a] -= margin;
        q.max[a] += margin;
    }
    return q;
}

float tw_cull_near_reach(const struct tw_view *v)
{
    return v->near_radius > v->near_plane ? v->near_radius : v->near_plane;
}

bool tw_cull_near_box(const struct tw_view *v, const struct tw_box *b, const float offset[3])
{
    const float r = tw_cull_near_reach(v);
    /* The box a query would draw, margin included (DESIGN §5): that is the
     * box the near plane must not cut. */
    const struct tw_box q = tw_cull_query_box(v->eye, b, offset);
    const float d = tw_cull_box_distance(v, &q, NULL);
    /* A little slack over the exact radius: a box that the near plane cuts
     * must never be queried. */
    return d <= r * 1.01f + 1e-4f;
}

bool tw_cull_box_screen_rect(const struct tw_view *v, const struct tw_box *b,
                             const float offset[3], float lo[2], float hi[2], float *w_min)
{
    /* view_proj and view_proj_rz differ only in their z row: x, y and w are
     * the same for either depth convention. */
    const float *m = v->view_proj;
    float min[3];
    for (int a = 0; a < 3; a++)
        min[a] = b->min[a] + (offset ? offset[a] : 0.0f);
    /* Corner (min) and the three edge vectors in clip space (x, y, w); the
     * other corners are sums of them. */
    static const int row[3] = {0, 1, 3};
    float base[3], edge[3][3];
    for (int r = 0; r < 3; r++) {
        const int i = row[r];
        base[r] = m[i] * min[0] + m[4 + i] * min[1] + m[8 + i] * min[2] + m[12 + i];
        for (int a = 0; a < 3; a++)
            edge[a][r] = m[4 * a + i] * (b->max[a] - b->min[a]);
    }
    lo[0] = lo[1] = INFINITY;
    hi[0] = hi[1] = -INFINITY;
    *w_min = INFINITY;
    for (int c = 0; c < 8; c++) {
        float p[3];
        for (int r = 0; r < 3; r++)
            p[r] = base[r] + (c & 1 ? edge[0][r] : 0.0f) + (c & 2 ? edge[1][r] : 0.0f) +
                   (c & 4 ? edge[2][r] : 0.0f);
        if (!(p[2] > v->near_plane))
            return false;
        for (int a = 0; a < 2; a++) {
            const float ndc = p[a] / p[2];
            lo[a] = ndc < lo[a] ? ndc : lo[a];
            hi[a] = ndc > hi[a] ? ndc : hi[a];
        }
        *w_min = p[2] < *w_min ? p[2] : *w_min;
    }
    return lo[0] <= hi[0] && lo[1] <= hi[1];
}

float tw_cull_box_screen_fraction(const struct tw_view *v, const struct tw_box *b,
                                  const float offset[3])
{
    float lo[2], hi[2], w_min;
    if (!tw_cull_box_screen_rect(v, b, offset, lo, hi, &w_min))
        return 1.0f;
    float area = 1.0f;
    for (int a = 0; a < 2; a++) {
        const float extent = fminf(hi[a], 1.0f) - fmaxf(lo[a], -1.0f);
        area *= extent > 0.0f ? 0.5f * extent : 0.0f;
    }
    return area;
}

float tw_cull_box_distance(const struct tw_view *v, const struct tw_box *b, const float offset[3])
{
    const float p[3] = {v->eye[0] - (offset ? offset[0] : 0.0f),
                        v->eye[1] - (offset ? offset[1] : 0.0f),
                        v->eye[2] - (offset ? offset[2] : 0.0f)};
    return sqrtf(tw_box_distance2(b, p));
}

static int compare_cells(const void *a, const void *b)
{
    return tw_cull_cell_order(a, b);
}

/* The cells [*lo, *hi] along one axis that a box [box_lo, box_hi] placed at
 * them can bring within r of eye, for cells of size: computed in double and
 * range-checked before any conversion to int64_t. False if there are none
 * (or the inputs are not finite). */
static bool axis_range(double eye, double r, double box_lo, double box_hi, double size,
                       int64_t *lo, int64_t *hi)
{
    const double a = floor((eye - r - box_hi) / size);
    const double b = floor((eye + r - box_lo) / size);
    if (!isfinite(a) || !isfinite(b) || a > b)
        return false;
    /* Cells beyond +-2^62 of the camera's are out of any scan budget. */
    const double limit = 4.0e18;
    *lo = (int64_t)fmax(a, -limit);
    *hi = (int64_t)fmin(b, limit);
    return true;
}

/* Narrows [*lo, *hi] to at most n cells, keeping those nearest cell 0 (the
 * camera's). */
static void clamp_range(int64_t *lo, int64_t *hi, uint64_t n)
{
    if ((uint64_t)(*hi - *lo) < n)
        return;
    int64_t a = *lo > -(int64_t)(n / 2) ? *lo : -(int64_t)(n / 2);
    int64_t b = a + (int64_t)n - 1;
    if (b > *hi) {
        b = *hi;
        a = b - (int64_t)n + 1;
    }
    *lo = a;
    *hi = b;
}

size_t tw_cull_cells_in_view_scan(const struct tw_view *v, const struct tw_box *common_box,
                                  float w, float d, struct tw_cull_cell *out, size_t cap,
                                  struct tw_cull_scan *scan)
{
    struct tw_cull_scan st = {0, false};
    size_t n = 0;
    const float R = v->view_distance;
    int64_t i0, i1, j0, j1;
    if (!isfinite(w) || !isfinite(d) || !(w > 0.0f) || !(d > 0.0f) || !(R >= 0.0f) ||
        !isfinite(R) || tw_box_is_empty(common_box) ||
        !axis_range(v->eye[0], R, common_box->min[0], common_box->max[0], w, &i0, &i1) ||
        !axis_range(v->eye[2], R, common_box->min[2], common_box->max[2], d, &j0, &j1))
        goto done;
    /* Bounded work per frame whatever the tileset: at most
     * TW_TILES_MAX_CELLS_IN_VIEW cells are tested, the nearest square of them. */
    const uint64_t budget = TW_TILES_MAX_CELLS_IN_VIEW;
    const uint64_t ni = (uint64_t)(i1 - i0) + 1, nj = (uint64_t)(j1 - j0) + 1;
    if (ni > budget || nj > budget || ni * nj > budget) {
        st.truncated = true;
        uint64_t side = 1;
        while ((side + 1) * (side + 1) <= budget)
            side++;
        if (ni <= side)
            clamp_range(&j0, &j1, budget / ni);
        else if (nj <= side)
            clamp_range(&i0, &i1, budget / nj);
        else {
            clamp_range(&i0, &i1, side);
            clamp_range(&j0, &j1, side);
        }
    }
    for (int64_t di = i0; di <= i1; di++) {
        for (int64_t dj = j0; dj <= j1; dj++) {
            st.cells_tested++;
            const struct tw_cell cell = {(int64_t)((uint64_t)v->cell.i + (uint64_t)di),
                                         (int64_t)((uint64_t)v->cell.j + (uint64_t)dj)};
            float off[3];
            tw_tiles_cell_offset(cell, v->cell, w, d, off);
            const float dist = tw_cull_box_distance(v, common_box, off);
            if (!(dist <= R))
                continue;
            if (tw_cull_frustum_box(&v->frustum, common_box, off) == TW_CULL_OUTSIDE)
                continue;
            if (n < cap) {
                out[n].cell = cell;
                out[n].distance = dist;
                out[n].level = 0;
            }
            n++;
        }
    }
    /* qsort() wants a valid pointer even for no elements. */
    if (n > 1 && n <= cap)
        qsort(out, n, sizeof(*out), compare_cells);
done:
    if (scan)
        *scan = st;
    return n;
}

size_t tw_cull_cells_in_view(const struct tw_view *v, const struct tw_box *common_box,
                             float w, float d, struct tw_cull_cell *out, size_t cap)
{
    return tw_cull_cells_in_view_scan(v, common_box, w, d, out, cap, NULL);
}

uint32_t tw_cull_vfc_tile(const struct tw_view *v, const struct tw_prototype *proto,
                          const float offset[3], uint32_t *out)
{
    uint32_t n = 0;
    for (uint32_t c = 0; c < proto->cluster_count; c++) {
        const struct tw_box *b = &proto->clusters[c].box;
        if (tw_cull_box_distance(v, b, offset) > v->view_distance)
            continue;
        if (tw_cull_frustum_box(&v->frustum, b, offset) == TW_CULL_OUTSIDE)
            continue;
        out[n++] = c;
    }
    return n;
}
