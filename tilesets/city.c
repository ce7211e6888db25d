/* The procedural city tileset (tilesets.h, DESIGN.md §10).
 *
 * A tile is one city block seen from the streets around it: the tile spans
 * [0, W] x [0, W], half of every street lies inside each border, so the
 * block's lots cover [s, W - s] with s = street_width / 2. Buildings are
 * generated from a small parameter record (struct building_spec) by a pure
 * function; equal records share one set of meshes, so rows of identical
 * houses, matching corner towers and repeated types across prototypes are
 * instanced rather than duplicated. Each building is three meshes (walls,
 * glass, roof) because a material belongs to an instance. */
#include "tilesets/mesh-builder.h"
#include "tilesets/procedural.h"
#include "tilesets/tilesets-private.h"
#include "tiles/array.h"
#include "tiles/tiles-internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const float kerb_height = 0.15f;
/* Building heights are drawn in steps of this many metres. */
static const float height_step = 0.5f;

/* Dimensions are snapped to a grid so that independently drawn buildings
 * coincide now and then and can share meshes. */
static float quantize(float x, float step)
{
    return step * floorf(x / step + 0.5f);
}

static float clampf(float x, float lo, float hi)
{
    return x < lo ? lo : x > hi ? hi : x;
}

/* ---- mesh building ----------------------------------------------------------- */

/* Emits a planar convex polygon as a triangle fan with its own vertices and
 * the face normal. The winding is made counter-clockwise seen from the side
 * that facing points to, because the renderer culls back faces. Degenerate
 * polygons are dropped (in both modes, so that counts agree). */
static void emit_polygon(struct tw_mesh_builder *b, const float p[][3], uint32_t n,
                         const float facing[3])
{
    if (b->err)
        return;
    const float e1[3] = {p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]};
    const float e2[3] = {p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]};
    float c[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                  e1[0] * e2[1] - e1[1] * e2[0]};
    const float len = sqrtf(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
    if (!(len > 1e-6f))
        return;
    const bool flip = c[0] * facing[0] + c[1] * facing[1] + c[2] * facing[2] < 0.0f;
    const float sign = flip ? -1.0f / len : 1.0f / len;
    for (int k = 0; k < 3; k++)
        c[k] *= sign;
    if (b->count_only) {
        b->vertex_count += n;
        b->triangle_count += n - 2;
        return;
    }
    if (!tw_mesh_builder_reserve(b, n, n - 2))
        return;
    const uint32_t base = b->vertex_count;
    for (uint32_t v = 0; v < n; v++) {
        const float *q = p[flip ? (n - v) % n : v];
        memcpy(b->positions + 3 * (size_t)(base + v), q, sizeof(float) * 3);
        memcpy(b->normals + 3 * (size_t)(base + v), c, sizeof(float) * 3);
    }
    for (uint32_t t = 0; t + 2 < n; t++) {
        uint32_t *tri = b->indices + 3 * (size_t)(b->triangle_count + t);
        tri[0] = base;
        tri[1] = base + t + 1;
        tri[2] = base + t + 2;
    }
    b->vertex_count += n;
    b->triangle_count += n - 2;
}

static void emit_quad(struct tw_mesh_builder *b, const float p0[3], const float p1[3],
                      const float p2[3], const float p3[3], const float facing[3])
{
    float p[4][3];
    memcpy(p[0], p0, sizeof(p[0]));
    memcpy(p[1], p1, sizeof(p[1]));
    memcpy(p[2], p2, sizeof(p[2]));
    memcpy(p[3], p3, sizeof(p[3]));
    emit_polygon(b, (const float(*)[3])p, 4, facing);
}

enum box_face {
    FACE_NX = 1 << 0, FACE_PX = 1 << 1,
    FACE_NY = 1 << 2, FACE_PY = 1 << 3,
    FACE_NZ = 1 << 4, FACE_PZ = 1 << 5,
    FACES_SIDES = FACE_NX | FACE_PX | FACE_NZ | FACE_PZ,
    FACES_NO_BOTTOM = FACES_SIDES | FACE_PY,
};

/* The faces of an axis-aligned box selected by mask. */
static void emit_box(struct tw_mesh_builder *b, const float lo[3], const float hi[3], unsigned mask)
{
    for (int axis = 0; axis < 3; axis++) {
        const int u = (axis + 1) % 3, v = (axis + 2) % 3;
        for (int side = 0; side < 2; side++) {
            if (!(mask & (1u << (2 * axis + side))))
                continue;
            float facing[3] = {0, 0, 0};
            facing[axis] = side ? 1.0f : -1.0f;
            float p[4][3];
            for (int k = 0; k < 4; k++) {
                p[k][axis] = side ? hi[axis] : lo[axis];
                p[k][u] = (k == 1 || k == 2) ? hi[u] : lo[u];
                p[k][v] = (k >= 2) ? hi[v] : lo[v];
            }
            emit_polygon(b, (const float(*)[3])p, 4, facing);
        }
    }
}

/* A vertical prism with a regular polygon section, sides and top. */
static void emit_prism(struct tw_mesh_builder *b, float cx, float cz, float radius, float y0,
                       float y1, uint32_t sides, bool top)
{
    float ring[16][2];
    if (sides > 16)
        sides = 16;
    for (uint32_t k = 0; k < sides; k++) {
        const double a = 2.0 * 3.14159265358979323846 * k / sides;
        ring[k][0] = cx + radius * (float)cos(a);
        ring[k][1] = cz + radius * (float)sin(a);
    }
    for (uint32_t k = 0; k < sides; k++) {
        const float *a = ring[k], *c = ring[(k + 1) % sides];
        const float p0[3] = {a[0], y0, a[1]}, p1[3] = {c[0], y0, c[1]};
        const float p2[3] = {c[0], y1, c[1]}, p3[3] = {a[0], y1, a[1]};
        const float facing[3] = {(a[0] + c[0]) * 0.5f - cx, 0.0f, (a[1] + c[1]) * 0.5f - cz};
        emit_quad(b, p0, p1, p2, p3, facing);
    }
    if (top) {
        float p[16][3];
        for (uint32_t k = 0; k < sides; k++) {
            p[k][0] = ring[k][0];
            p[k][1] = y1;
            p[k][2] = ring[k][1];
        }
        const float up[3] = {0, 1, 0};
        emit_polygon(b, (const float(*)[3])p, sides, up);
    }
}

/* ---- facades ------------------------------------------------------------------- */

/* One wall of a rectangular tier: s runs along it from one corner to the
 * next (going round the rectangle), t is the offset along the outward
 * normal, y is height. */
struct facade {
    float origin[3];
    float along[3];
    float out[3];
    float len;
};

static void facade_point(const struct facade *f, float s, float y, float t, float p[3])
{
    for (int k = 0; k < 3; k++)
        p[k] = f->origin[k] + s * f->along[k] + t * f->out[k];
    p[1] += y;
}

/* The quadrilateral of the facade points st[k] = (s, y, t), facing. */
static void facade_quad(struct tw_mesh_builder *b, const struct facade *f, const float st[4][3],
                        const float facing[3])
{
    float p[4][3];
    for (int k = 0; k < 4; k++)
        facade_point(f, st[k][0], st[k][1], st[k][2], p[k]);
    emit_polygon(b, (const float(*)[3])p, 4, facing);
}

/* A rectangle parallel to the wall at offset t, facing out (dir > 0) or in. */
static void facade_face(struct tw_mesh_builder *b, const struct facade *f, float s0, float s1,
                        float y0, float y1, float t, float dir)
{
    const float st[4][3] = {{s0, y0, t}, {s1, y0, t}, {s1, y1, t}, {s0, y1, t}};
    const float facing[3] = {dir * f->out[0], dir * f->out[1], dir * f->out[2]};
    facade_quad(b, f, st, facing);
}

/* A rectangle across the wall at s (a window jamb, the end of a fin). */
static void facade_jamb(struct tw_mesh_builder *b, const struct facade *f, float s, float y0,
                        float y1, float t0, float t1, float dir)
{
    const float st[4][3] = {{s, y0, t0}, {s, y0, t1}, {s, y1, t1}, {s, y1, t0}};
    const float facing[3] = {dir * f->along[0], dir * f->along[1], dir * f->along[2]};
    facade_quad(b, f, st, facing);
}

/* A horizontal rectangle at height y, facing up (dir > 0) or down. */
static void facade_flat(struct tw_mesh_builder *b, const struct facade *f, float s0, float s1,
                        float y, float t0, float t1, float dir)
{
    const float st[4][3] = {{s0, y, t0}, {s1, y, t0}, {s1, y, t1}, {s0, y, t1}};
    const float facing[3] = {0.0f, dir, 0.0f};
    facade_quad(b, f, st, facing);
}

/* A horizontal strip along the whole wall between offsets t0 and t1, mitred
 * at 45 degrees so that the strips of the four walls of a rectangle meet
 * without overlapping (ledges, cornices, parapet tops). */
static void facade_mitre(struct tw_mesh_builder *b, const struct facade *f, float y, float t0,
                         float t1, float dir)
{
    const float st[4][3] = {
        {-t0, y, t0}, {f->len + t0, y, t0}, {f->len + t1, y, t1}, {-t1, y, t1}};
    const float facing[3] = {0.0f, dir, 0.0f};
    facade_quad(b, f, st, facing);
}

/* A ledge running round the building: protrudes by depth between y0 and y1. */
static void facade_ledge(struct tw_mesh_builder *b, const struct facade *f, float y0, float y1,
                         float depth)
{
    facade_face(b, f, -depth, f->len + depth, y0, y1, depth, 1.0f);
    facade_mitre(b, f, y1, 0.0f, depth, 1.0f);
    facade_mitre(b, f, y0, 0.0f, depth, -1.0f);
}

static void facade_parapet(struct tw_mesh_builder *b, const struct facade *f, float y0, float y1,
                           float thickness)
{
    facade_face(b, f, 0.0f, f->len, y0, y1, 0.0f, 1.0f);
    facade_mitre(b, f, y1, 0.0f, -thickness, 1.0f);
    facade_face(b, f, thickness, f->len - thickness, y0, y1, -thickness, -1.0f);
}

/* A window recessed by depth: four reveals in the wall material, the pane
 * in the glass material. */
static void facade_window(struct tw_mesh_builder *wall, struct tw_mesh_builder *glass,
                          const struct facade *f, float s0, float s1, float y0, float y1,
                          float depth)
{
    facade_jamb(wall, f, s0, y0, y1, -depth, 0.0f, 1.0f);
    facade_jamb(wall, f, s1, y0, y1, -depth, 0.0f, -1.0f);
    facade_flat(wall, f, s0, s1, y1, -depth, 0.0f, -1.0f);
    facade_flat(wall, f, s0, s1, y0, -depth, 0.0f, 1.0f);
    facade_face(glass, f, s0, s1, y0, y1, -depth, 1.0f);
}

/* A protruding stone sill under a window. */
static void facade_sill(struct tw_mesh_builder *b, const struct facade *f, float s0, float s1,
                        float y)
{
    const float over = 0.08f, depth = 0.12f, height = 0.1f;
    s0 -= over;
    s1 += over;
    facade_flat(b, f, s0, s1, y, 0.0f, depth, 1.0f);
    facade_face(b, f, s0, s1, y - height, y, depth, 1.0f);
    facade_flat(b, f, s0, s1, y - height, 0.0f, depth, -1.0f);
    facade_jamb(b, f, s0, y - height, y, 0.0f, depth, -1.0f);
    facade_jamb(b, f, s1, y - height, y, 0.0f, depth, 1.0f);
}

/* A cross of glazing bars in a recessed window, standing on the pane. */
static void facade_glazing_bars(struct tw_mesh_builder *b, const struct facade *f, float s0,
                                float s1, float y0, float y1, float depth)
{
    const float half = 0.035f, t = -depth, front = -depth + 0.06f;
    const float sm = 0.5f * (s0 + s1), ym = y0 + 0.62f * (y1 - y0);
    facade_face(b, f, sm - half, sm + half, y0, y1, front, 1.0f);
    facade_jamb(b, f, sm - half, y0, y1, t, front, -1.0f);
    facade_jamb(b, f, sm + half, y0, y1, t, front, 1.0f);
    facade_face(b, f, s0, s1, ym - half, ym + half, front, 1.0f);
    facade_flat(b, f, s0, s1, ym + half, t, front, 1.0f);
    facade_flat(b, f, s0, s1, ym - half, t, front, -1.0f);
}

/* A balcony in front of a window of the floor starting at y: a slab and a
 * solid railing. It protrudes 0.9 m, less than the 1 m between a lot line
 * and the street band. The slab floats 0.25 m up so that its faces never
 * coincide with a ledge's. */
static void facade_balcony(struct tw_mesh_builder *b, const struct facade *f, float s0, float s1,
                           float y)
{
    const float depth = 0.9f, rail = 0.06f;
    s0 -= 0.25f;
    s1 += 0.25f;
    const float y0 = y + 0.25f, y1 = y + 0.4f, y2 = y + 1.4f;
    facade_face(b, f, s0, s1, y0, y1, depth, 1.0f);
    facade_flat(b, f, s0, s1, y1, 0.0f, depth, 1.0f);
    facade_flat(b, f, s0, s1, y0, 0.0f, depth, -1.0f);
    facade_jamb(b, f, s0, y0, y1, 0.0f, depth, -1.0f);
    facade_jamb(b, f, s1, y0, y1, 0.0f, depth, 1.0f);
    facade_face(b, f, s0, s1, y1, y2, depth, 1.0f);
    facade_face(b, f, s0, s1, y1, y2, depth - rail, -1.0f);
    facade_flat(b, f, s0, s1, y2, depth - rail, depth, 1.0f);
    facade_jamb(b, f, s0, y1, y2, depth - rail, depth, -1.0f);
    facade_jamb(b, f, s1, y1, y2, depth - rail, depth, 1.0f);
}

/* A drip moulding over a window: a small protruding cap. */
static void facade_hood(struct tw_mesh_builder *b, const struct facade *f, float s0, float s1,
                        float y)
{
    const float over = 0.12f, depth = 0.15f, height = 0.18f;
    s0 -= over;
    s1 += over;
    facade_flat(b, f, s0, s1, y + height, 0.0f, depth, 1.0f);
    facade_face(b, f, s0, s1, y, y + height, depth, 1.0f);
    facade_flat(b, f, s0, s1, y, 0.0f, depth, -1.0f);
    facade_jamb(b, f, s0, y, y + height, 0.0f, depth, -1.0f);
    facade_jamb(b, f, s1, y, y + height, 0.0f, depth, 1.0f);
}

/* ---- buildings ------------------------------------------------------------------ */

enum facade_style {
    STYLE_CLASSIC,  /* punched windows with sills, ledges every few floors */
    STYLE_MODERN,   /* punched windows, sparse ledges */
    STYLE_RIBBON,   /* a glass band per floor divided by mullions */
};

enum roof_feature {
    ROOF_PLAIN,
    ROOF_PENTHOUSE,
    ROOF_TANK,
};

/* Everything a building's meshes depend on: equal specs give equal meshes. */
struct building_spec {
    float w, d;             /* footprint along mesh-local x and z */
    float ground_h, floor_h;
    uint32_t floors;        /* of the base tier, ground floor included */
    uint32_t upper_floors;  /* of the set-back tier; 0: none */
    float inset;            /* set-back on every side */
    float base_bay;         /* window spacing before the triangle budget */
    float bay;              /* window spacing used */
    float window_ratio;     /* window width / bay */
    float recess;
    float parapet_h;
    uint32_t style;
    uint32_t ledge_every;   /* 0: no intermediate ledges */
    uint32_t blank_mask;    /* base-tier walls without windows (party walls) */
    uint32_t roof;
    uint32_t detail;        /* seeds the rooftop clutter */
    bool balconies;         /* on upper floors of punched facades */
};

static bool spec_equal(const struct building_spec *a, const struct building_spec *b)
{
    return a->w == b->w && a->d == b->d && a->ground_h == b->ground_h &&
           a->floor_h == b->floor_h && a->floors == b->floors &&
           a->upper_floors == b->upper_floors && a->inset == b->inset &&
           a->base_bay == b->base_bay && a->bay == b->bay &&
           a->window_ratio == b->window_ratio && a->recess == b->recess &&
           a->parapet_h == b->parapet_h && a->style == b->style &&
           a->ledge_every == b->ledge_every && a->blank_mask == b->blank_mask &&
           a->roof == b->roof && a->detail == b->detail &&
           a->balconies == b->balconies;
}

/* Height of what stands on the top roof, parapet included. */
static float roof_extra(const struct building_spec *sp)
{
    const float clutter = sp->roof == ROOF_PENTHOUSE ? 3.4f : sp->roof == ROOF_TANK ? 3.0f : 1.4f;
    return fmaxf(clutter, sp->parapet_h);
}

static float min_bay(uint32_t style)
{
    return style == STYLE_RIBBON ? 1.1f : style == STYLE_CLASSIC ? 1.9f : 1.7f;
}

/* Party walls are blank only on buildings low enough to be hidden by their
 * neighbours; a tower's would show as a huge blank face. */
static uint32_t party_walls(float height, uint32_t blank_mask)
{
    return height <= 32.0f ? blank_mask : 0u;
}

/* Draws a building of footprint w x d whose top (roof clutter included)
 * stays at or below height. */
static void spec_init(struct building_spec *sp, struct tw_rng *r, float w, float d, float height,
                      uint32_t style, uint32_t blank_mask, bool allow_setback)
{
    memset(sp, 0, sizeof(*sp));
    sp->w = w;
    sp->d = d;
    sp->style = style;
    sp->blank_mask = party_walls(height, blank_mask);
    sp->floor_h = quantize(tw_rng_range(r, 3.1f, 3.6f), 0.1f);
    sp->ground_h = quantize(tw_rng_range(r, 3.9f, 4.8f), 0.1f);
    sp->parapet_h = quantize(tw_rng_range(r, 0.6f, 1.2f), 0.1f);
    switch (style) {
    case STYLE_CLASSIC:
        sp->recess = quantize(tw_rng_range(r, 0.2f, 0.35f), 0.05f);
        sp->window_ratio = quantize(tw_rng_range(r, 0.42f, 0.55f), 0.05f);
        sp->base_bay = quantize(tw_rng_range(r, 2.6f, 3.4f), 0.1f);
        sp->ledge_every = 2 + tw_rng_below(r, 3);
        break;
    case STYLE_MODERN:
        sp->recess = quantize(tw_rng_range(r, 0.15f, 0.3f), 0.05f);
        sp->window_ratio = quantize(tw_rng_range(r, 0.5f, 0.7f), 0.05f);
        sp->base_bay = quantize(tw_rng_range(r, 2.8f, 3.8f), 0.1f);
        sp->ledge_every = tw_rng_chance(r, 0.5f) ? 0 : 4 + tw_rng_below(r, 3);
        break;
    default:
        sp->recess = 0.15f;
        sp->window_ratio = 1.0f;
        sp->base_bay = quantize(tw_rng_range(r, 1.4f, 2.2f), 0.1f);
        sp->ledge_every = 0;
        break;
    }
    const uint32_t roll = tw_rng_below(r, 10);
    if (height > 18.0f && fminf(w, d) >= 9.0f)
        sp->roof = roll < 5 ? ROOF_PENTHOUSE : roll < 7 ? ROOF_TANK : ROOF_PLAIN;
    sp->detail = tw_rng_below(r, 4);

    /* The margin keeps float round-off in the summed floor heights from
     * pushing the top past height. */
    const float body = height - roof_extra(sp) - 0.01f;
    uint32_t floors = 1;
    if (body > sp->ground_h + sp->floor_h)
        floors = 1 + (uint32_t)floorf((body - sp->ground_h) / sp->floor_h);
    if (allow_setback && floors >= 12 && fminf(w, d) >= 16.0f && tw_rng_chance(r, 0.55f)) {
        sp->inset = quantize(tw_rng_range(r, 2.0f, fminf(w, d) * 0.2f), 0.5f);
        sp->upper_floors = (uint32_t)((float)floors * tw_rng_range(r, 0.25f, 0.5f));
        floors -= sp->upper_floors;
    }
    sp->floors = floors;
    sp->bay = sp->base_bay;
}

struct tier {
    float x0, z0, x1, z1;
    float y_base;
    uint32_t floors;
    bool ground;       /* the first floor is the taller ground floor */
};

static float floor_height(const struct building_spec *sp, const struct tier *t, uint32_t i)
{
    return t->ground && i == 0 ? sp->ground_h : sp->floor_h;
}

static float tier_top(const struct building_spec *sp, const struct tier *t)
{
    float y = t->y_base;
    for (uint32_t i = 0; i < t->floors; i++)
        y += floor_height(sp, t, i);
    return y;
}

static struct facade tier_facade(const struct tier *t, int k)
{
    /* Walls in order round the rectangle: -z, +x, +z, -x. */
    const float corners[4][2] = {{t->x0, t->z0}, {t->x1, t->z0}, {t->x1, t->z1}, {t->x0, t->z1}};
    static const float outs[4][3] = {{0, 0, -1}, {1, 0, 0}, {0, 0, 1}, {-1, 0, 0}};
    const float *a = corners[k], *b = corners[(k + 1) % 4];
    struct facade f;
    f.origin[0] = a[0];
    f.origin[1] = 0.0f;
    f.origin[2] = a[1];
    f.len = fabsf(b[0] - a[0]) + fabsf(b[1] - a[1]);
    f.along[0] = (b[0] - a[0]) / f.len;
    f.along[1] = 0.0f;
    f.along[2] = (b[1] - a[1]) / f.len;
    memcpy(f.out, outs[k], sizeof(f.out));
    return f;
}

/* Walls, windows and ledges of one wall of a tier. */
static void emit_wall(struct tw_mesh_builder *wall, struct tw_mesh_builder *glass,
                      const struct building_spec *sp, const struct tier *t,
                      const struct facade *f, bool blank)
{
    const float top = tier_top(sp, t);
    const float margin = sp->style == STYLE_RIBBON ? 0.4f : 0.5f;
    const float usable = f->len - 2.0f * margin;
    const uint32_t columns = usable > 1.2f ? (uint32_t)fmaxf(1.0f, floorf(usable / sp->bay + 0.5f)) : 0;

    if (blank || columns == 0) {
        facade_face(wall, f, 0.0f, f->len, t->y_base, top, 0.0f, 1.0f);
    } else {
        const float bay = usable / (float)columns;
        float y = t->y_base, band_bottom = t->y_base;
        for (uint32_t i = 0; i < t->floors; i++) {
            const bool shop = t->ground && i == 0;
            const float hf = floor_height(sp, t, i);
            const float sill = y + (shop ? 0.45f : 0.85f);
            const float head = y + hf - (shop ? 0.55f : 0.45f);
            /* The wall between this window row and the previous one. */
            facade_face(wall, f, 0.0f, f->len, band_bottom, sill, 0.0f, 1.0f);
            if (sp->style == STYLE_RIBBON) {
                const float s0 = margin, s1 = f->len - margin, fin = 0.07f;
                facade_face(wall, f, 0.0f, s0, sill, head, 0.0f, 1.0f);
                facade_face(wall, f, s1, f->len, sill, head, 0.0f, 1.0f);
                facade_window(wall, glass, f, s0, s1, sill, head, sp->recess);
                for (uint32_t j = 1; j < columns; j++) {
                    const float s = margin + bay * (float)j;
                    facade_face(wall, f, s - fin, s + fin, sill, head, 0.0f, 1.0f);
                    facade_jamb(wall, f, s - fin, sill, head, -sp->recess, 0.0f, -1.0f);
                    facade_jamb(wall, f, s + fin, sill, head, -sp->recess, 0.0f, 1.0f);
                }
            } else {
                const float ratio = shop ? fminf(0.85f, sp->window_ratio + 0.2f) : sp->window_ratio;
                const float ww = bay * ratio;
                float pier = 0.0f;
                for (uint32_t j = 0; j < columns; j++) {
                    const float s0 = margin + bay * (float)j + 0.5f * (bay - ww);
                    facade_face(wall, f, pier, s0, sill, head, 0.0f, 1.0f);
                    facade_window(wall, glass, f, s0, s0 + ww, sill, head, sp->recess);
                    if (sp->balconies && !shop)
                        facade_balcony(wall, f, s0, s0 + ww, y);
                    if (sp->style == STYLE_CLASSIC && !shop) {
                        facade_glazing_bars(wall, f, s0, s0 + ww, sill, head, sp->recess);
                        facade_sill(wall, f, s0, s0 + ww, sill);
                        facade_hood(wall, f, s0, s0 + ww, head + 0.05f);
                    }
                    pier = s0 + ww;
                }
                facade_face(wall, f, pier, f->len, sill, head, 0.0f, 1.0f);
            }
            band_bottom = head;
            y += hf;
        }
        facade_face(wall, f, 0.0f, f->len, band_bottom, top, 0.0f, 1.0f);
    }

    /* Ledges run round every wall, blank ones too, so that they close at
     * the corners. */
    float y = t->y_base;
    for (uint32_t i = 0; i + 1 < t->floors; i++) {
        y += floor_height(sp, t, i);
        if (t->ground && i == 0)
            facade_ledge(wall, f, y - 0.2f, y + 0.2f, 0.3f);
        else if (sp->ledge_every && (i + 1) % sp->ledge_every == 0)
            facade_ledge(wall, f, y - 0.15f, y + 0.15f, 0.2f);
    }
    facade_ledge(wall, f, top - 0.5f, top, 0.4f);
    facade_parapet(wall, f, top, top + sp->parapet_h, 0.3f);
}

static bool rects_overlap(const float a[4], const float b[4])
{
    return a[0] < b[2] && b[0] < a[2] && a[1] < b[3] && b[1] < a[3];
}

/* Penthouse, water tank and air-conditioning units on the top roof. */
static void emit_roof_clutter(struct tw_mesh_builder *wall, struct tw_mesh_builder *roof,
                              const struct building_spec *sp, const struct tier *t, float top)
{
    struct tw_rng r = tw_rng_seeded(sp->detail, (int64_t)(sp->w * 16.0f), (int64_t)(sp->d * 16.0f));
    const float margin = 0.9f;
    const float ax = t->x0 + margin, az = t->z0 + margin;
    const float aw = t->x1 - t->x0 - 2.0f * margin, ad = t->z1 - t->z0 - 2.0f * margin;
    if (aw < 3.0f || ad < 3.0f)
        return;
    float taken[4] = {0, 0, 0, 0};
    bool has_taken = false;
    if (sp->roof == ROOF_PENTHOUSE) {
        const float pw = aw * tw_rng_range(&r, 0.3f, 0.5f), pd = ad * tw_rng_range(&r, 0.3f, 0.5f);
        const float px = ax + (aw - pw) * tw_rng_float(&r), pz = az + (ad - pd) * tw_rng_float(&r);
        const float lo[3] = {px, top, pz}, hi[3] = {px + pw, top + 3.4f, pz + pd};
        emit_box(wall, lo, hi, FACES_SIDES);
        emit_box(roof, lo, hi, FACE_PY);
        taken[0] = px; taken[1] = pz; taken[2] = px + pw; taken[3] = pz + pd;
        has_taken = true;
    } else if (sp->roof == ROOF_TANK) {
        const float radius = fminf(1.4f, 0.25f * fminf(aw, ad));
        const float cx = ax + radius + (aw - 2.0f * radius) * tw_rng_float(&r);
        const float cz = az + radius + (ad - 2.0f * radius) * tw_rng_float(&r);
        const float lo[3] = {cx - radius, top, cz - radius};
        const float hi[3] = {cx + radius, top + 0.8f, cz + radius};
        emit_box(roof, lo, hi, FACES_NO_BOTTOM);
        emit_prism(roof, cx, cz, radius, top + 0.8f, top + 3.0f, 8, true);
        taken[0] = lo[0]; taken[1] = lo[2]; taken[2] = hi[0]; taken[3] = hi[2];
        has_taken = true;
    }
    const uint32_t units = 1 + tw_rng_below(&r, 4);
    for (uint32_t u = 0; u < units; u++) {
        const float uw = tw_rng_range(&r, 1.0f, 2.2f), ud = tw_rng_range(&r, 1.0f, 2.0f);
        const float uh = tw_rng_range(&r, 0.8f, 1.4f);
        if (uw > aw || ud > ad)
            continue;
        for (int attempt = 0; attempt < 4; attempt++) {
            const float ux = ax + (aw - uw) * tw_rng_float(&r), uz = az + (ad - ud) * tw_rng_float(&r);
            const float rect[4] = {ux, uz, ux + uw, uz + ud};
            if (has_taken && rects_overlap(rect, taken))
                continue;
            const float lo[3] = {ux, top, uz}, hi[3] = {ux + uw, top + uh, uz + ud};
            emit_box(roof, lo, hi, FACES_NO_BOTTOM);
            break;
        }
    }
}

/* The whole building, in mesh-local coordinates: footprint [0, w] x [0, d],
 * ground at y = 0. */
static void emit_building(struct tw_mesh_builder *wall, struct tw_mesh_builder *glass,
                          struct tw_mesh_builder *roof, const struct building_spec *sp)
{
    struct tier tiers[2];
    uint32_t tier_count = 1;
    tiers[0] = (struct tier){0.0f, 0.0f, sp->w, sp->d, 0.0f, sp->floors, true};
    if (sp->upper_floors) {
        tiers[1] = (struct tier){sp->inset, sp->inset, sp->w - sp->inset, sp->d - sp->inset,
                                 tier_top(sp, &tiers[0]), sp->upper_floors, false};
        tier_count = 2;
    }
    const float up[3] = {0, 1, 0};
    for (uint32_t k = 0; k < tier_count; k++) {
        const struct tier *t = &tiers[k];
        const float top = tier_top(sp, t);
        for (int side = 0; side < 4; side++) {
            const struct facade f = tier_facade(t, side);
            emit_wall(wall, glass, sp, t, &f, k == 0 && (sp->blank_mask >> side & 1u));
        }
        if (k + 1 < tier_count) {
            /* A terrace: the roof round the foot of the next tier. */
            const struct tier *n = &tiers[k + 1];
            const float strips[4][4] = {
                {t->x0, t->z0, t->x1, n->z0}, {t->x0, n->z1, t->x1, t->z1},
                {t->x0, n->z0, n->x0, n->z1}, {n->x1, n->z0, t->x1, n->z1},
            };
            for (int s = 0; s < 4; s++) {
                const float p0[3] = {strips[s][0], top, strips[s][1]};
                const float p1[3] = {strips[s][2], top, strips[s][1]};
                const float p2[3] = {strips[s][2], top, strips[s][3]};
                const float p3[3] = {strips[s][0], top, strips[s][3]};
                emit_quad(roof, p0, p1, p2, p3, up);
            }
        } else {
            const float p0[3] = {t->x0, top, t->z0}, p1[3] = {t->x1, top, t->z0};
            const float p2[3] = {t->x1, top, t->z1}, p3[3] = {t->x0, top, t->z1};
            emit_quad(roof, p0, p1, p2, p3, up);
            emit_roof_clutter(wall, roof, sp, t, top);
        }
    }
}

/* ---- the generator's state ---------------------------------------------------- */

enum { FACADE_COLOURS = 6 };
static const uint32_t no_mesh = UINT32_MAX;

struct cached_building {
    struct building_spec spec;
    uint32_t mesh[3];       /* wall, glass, roof; no_mesh when empty */
};

/* A building waiting for its final window spacing. */
struct lot {
    struct building_spec spec;
    float transform[12];
    uint32_t facade_material;
};

struct city {
    struct tw_tileset *ts;
    struct tw_city_settings set;
    float w;                /* tile side */
    float half_street;      /* s: the block's lots start here */
    float kerb_line;        /* where the road ends and the sidewalk begins */
    float lot_scale;        /* >= 1: lots grow with blocks wider than 66 m */

    uint32_t mat_asphalt, mat_sidewalk, mat_marking, mat_courtyard, mat_grass, mat_glass,
             mat_roof, mat_metal, mat_foliage, mat_bark, mat_water;
    uint32_t mat_facade[FACADE_COLOURS];

    uint32_t mesh_asphalt, mesh_sidewalk, mesh_markings, mesh_lot, mesh_lamps;
    uint32_t mesh_canopy, mesh_trunk, mesh_paths, mesh_fountain, mesh_water;
    bool park_meshes;       /* the five above are made */

    struct cached_building *cache;
    uint32_t cache_count, cache_cap;
    struct lot *lots;
    uint32_t lot_count, lot_cap;

    struct tw_mesh_builder wall, glass, roof;
};

static int add_mesh_from(struct city *c, struct tw_mesh_builder *b, uint32_t *mesh)
{
    if (!b->err && b->triangle_count == 0) {
        *mesh = no_mesh;
        return TW_OK;
    }
    return tw_mesh_builder_add_to(b, c->ts, mesh);
}

static uint64_t building_triangles(struct city *c, const struct building_spec *sp)
{
    tw_mesh_builder_reset(&c->wall, true);
    tw_mesh_builder_reset(&c->glass, true);
    tw_mesh_builder_reset(&c->roof, true);
    emit_building(&c->wall, &c->glass, &c->roof, sp);
    return (uint64_t)c->wall.triangle_count + c->glass.triangle_count + c->roof.triangle_count;
}

/* The meshes of a building, generated on first use. */
static int building_meshes(struct city *c, const struct building_spec *sp, uint32_t mesh[3])
{
    for (uint32_t k = 0; k < c->cache_count; k++) {
        if (spec_equal(&c->cache[k].spec, sp)) {
            memcpy(mesh, c->cache[k].mesh, sizeof(c->cache[k].mesh));
            return TW_OK;
        }
    }
    int err = tw_array_reserve_u32((void **)&c->cache, &c->cache_cap, c->cache_count + 1,
                                   sizeof(*c->cache), 64);
    if (err)
        return err;
    tw_mesh_builder_reset(&c->wall, false);
    tw_mesh_builder_reset(&c->glass, false);
    tw_mesh_builder_reset(&c->roof, false);
    emit_building(&c->wall, &c->glass, &c->roof, sp);
    struct cached_building *entry = &c->cache[c->cache_count];
    entry->spec = *sp;
    err = add_mesh_from(c, &c->wall, &entry->mesh[0]);
    if (!err)
        err = add_mesh_from(c, &c->glass, &entry->mesh[1]);
    if (!err)
        err = add_mesh_from(c, &c->roof, &entry->mesh[2]);
    if (err)
        return err;
    c->cache_count++;
    memcpy(mesh, entry->mesh, sizeof(entry->mesh));
    return TW_OK;
}

static int push_lot(struct city *c, const struct building_spec *sp, const float transform[12],
                    uint32_t facade_material)
{
    const int err = tw_array_reserve_u32((void **)&c->lots, &c->lot_cap, c->lot_count + 1,
                                         sizeof(*c->lots), 32);
    if (err)
        return err;
    struct lot *l = &c->lots[c->lot_count++];
    l->spec = *sp;
    memcpy(l->transform, transform, sizeof(l->transform));
    l->facade_material = facade_material;
    return TW_OK;
}

/* ---- placement ------------------------------------------------------------------ */

/* Quarter turns about y, exact: turn k maps local -z to the street of side
 * k (0: -z, 1: +x, 2: +z, 3: -x), local +x along side k and local +z into
 * the block. */
static const float turn_cos[4] = {1.0f, 0.0f, -1.0f, 0.0f};
static const float turn_sin[4] = {0.0f, -1.0f, 0.0f, 1.0f};

static void turn_transform(uint32_t k, float tx, float ty, float tz, float m[12])
{
    const float co = turn_cos[k & 3], si = turn_sin[k & 3];
    const float r[12] = {co, 0.0f, si, tx, 0.0f, 1.0f, 0.0f, ty, -si, 0.0f, co, tz};
    memcpy(m, r, sizeof(r));
}

/* Turn k about the tile's centre: the pieces of ground built for side 0
 * serve all four sides. */
static void turn_about_centre(const struct city *c, uint32_t k, float m[12])
{
    const float h = 0.5f * c->w, co = turn_cos[k & 3], si = turn_sin[k & 3];
    turn_transform(k, h - (co * h + si * h), 0.0f, h - (-si * h + co * h), m);
}

static void turn_point(const struct city *c, uint32_t k, float x, float y, float z, float p[3])
{
    float m[12];
    turn_about_centre(c, k, m);
    p[0] = m[0] * x + m[2] * z + m[3];
    p[1] = y;
    p[2] = m[8] * x + m[10] * z + m[11];
}

/* Side k of the block in tile coordinates: a point a along the side and b
 * into the block. */
static void side_frame(const struct city *c, uint32_t k, float origin[2], float along[2])
{
    const float lo = c->half_street, hi = c->w - c->half_street;
    const float origins[4][2] = {{lo, lo}, {hi, lo}, {hi, hi}, {lo, hi}};
    static const float alongs[4][2] = {{1, 0}, {0, 1}, {-1, 0}, {0, -1}};
    memcpy(origin, origins[k & 3], sizeof(float) * 2);
    memcpy(along, alongs[k & 3], sizeof(float) * 2);
}

static void side_transform(const struct city *c, uint32_t k, float a, float m[12])
{
    float origin[2], along[2];
    side_frame(c, k, origin, along);
    turn_transform(k, origin[0] + a * along[0], kerb_height, origin[1] + a * along[1], m);
}

/* A turned w x d footprint whose tile-space box starts at (x, z). */
static void rect_transform(uint32_t k, float w, float d, float x, float z, float m[12])
{
    turn_transform(k, 0.0f, kerb_height, 0.0f, m);
    float min_x = 0.0f, min_z = 0.0f;
    const float corners[4][2] = {{0, 0}, {w, 0}, {0, d}, {w, d}};
    for (int i = 0; i < 4; i++) {
        const float px = m[0] * corners[i][0] + m[2] * corners[i][1];
        const float pz = m[8] * corners[i][0] + m[10] * corners[i][1];
        min_x = i == 0 || px < min_x ? px : min_x;
        min_z = i == 0 || pz < min_z ? pz : min_z;
    }
    m[3] = x - min_x;
    m[11] = z - min_z;
}

/* ---- block layouts -------------------------------------------------------------- */

enum block_kind {
    BLOCK_DENSE,
    BLOCK_LOWRISE,
    BLOCK_PARK,
};

struct block_params {
    uint32_t side_mask;     /* sides of the block lined with buildings */
    float depth;            /* deepest side lot; corners are at least this */
    float corner_size[4];
    bool share_corners;
    float lot_min, lot_max; /* side-lot widths */
    float gap_chance;
    float row_chance;
    float side_h[2], corner_h[2];
    float tall_style_from;  /* buildings above this prefer modern styles */
};

static uint32_t pick_style(struct tw_rng *r, float height, float tall_from)
{
    const uint32_t roll = tw_rng_below(r, 20);
    if (height > tall_from)
        return roll < 8 ? STYLE_RIBBON : roll < 17 ? STYLE_MODERN : STYLE_CLASSIC;
    /* Curtain walls carry few triangles per square metre; low blocks need
     * the punched facades to reach their budget. */
    return roll < 12 ? STYLE_CLASSIC : STYLE_MODERN;
}

static float pick_height(struct tw_rng *r, const float range[2])
{
    return quantize(tw_rng_range(r, range[0], range[1]), height_step);
}

/* Lines side k with buildings from a = start to a = end; reports whether
 * buildings touch both ends (the corner buildings' party walls). */
static int layout_side(struct city *c, struct tw_rng *r, const struct block_params *bp,
                       uint32_t k, float start, float end, bool corner_before,
                       bool corner_after)
{
    const float avail = end - start;
    if (avail < bp->lot_min)
        return TW_OK;
    int err = TW_OK;
    if (tw_rng_chance(r, bp->row_chance)) {
        /* A terrace of identical houses: one mesh set, instanced. */
        const float target = tw_rng_range(r, bp->lot_min, bp->lot_max);
        const uint32_t n = (uint32_t)fmaxf(1.0f, floorf(avail / target + 0.5f));
        const float lw = avail / (float)n;
        const float depth = quantize(tw_rng_range(r, 0.7f * bp->depth, bp->depth), 0.5f);
        const float h = pick_height(r, bp->side_h);
        const uint32_t style = pick_style(r, h, bp->tall_style_from);
        struct building_spec base;
        spec_init(&base, r, lw, depth, h, style, 0, false);
        const uint32_t mat_a = c->mat_facade[tw_rng_below(r, FACADE_COLOURS)];
        const uint32_t mat_b = tw_rng_chance(r, 0.5f) ? c->mat_facade[tw_rng_below(r, FACADE_COLOURS)] : mat_a;
        for (uint32_t i = 0; i < n && !err; i++) {
            struct building_spec sp = base;
            sp.blank_mask = party_walls(h, ((i > 0 || corner_before) ? 1u << 3 : 0u) |
                                               ((i + 1 < n || corner_after) ? 1u << 1 : 0u));
            float m[12];
            side_transform(c, k, start + lw * (float)i, m);
            err = push_lot(c, &sp, m, i % 2 ? mat_b : mat_a);
        }
        return err;
    }

    /* Widths first, so that each building knows its neighbours. */
    float widths[64];
    bool gap[64];
    uint32_t n = 0;
    bool gap_used = false;
    float a = start;
    while (end - a > 0.01f && n < 64) {
        const float remaining = end - a;
        if (!gap_used && n > 0 && remaining > 2.0f * bp->lot_min + 6.0f &&
            tw_rng_chance(r, bp->gap_chance)) {
            widths[n] = quantize(tw_rng_range(r, 3.0f, 6.0f), 0.5f);
            gap[n++] = true;
            gap_used = true;
            a += widths[n - 1];
            continue;
        }
        float lw = quantize(tw_rng_range(r, bp->lot_min, bp->lot_max), 0.5f);
        if (remaining - lw < bp->lot_min)
            lw = remaining;
        widths[n] = lw;
        gap[n++] = false;
        a += lw;
    }
    if (end - a > 0.01f && n > 0)
        widths[n - 1] += end - a;
    a = start;
    for (uint32_t i = 0; i < n && !err; i++) {
        if (!gap[i]) {
            const bool before = i > 0 ? !gap[i - 1] : corner_before;
            const bool after = i + 1 < n ? !gap[i + 1] : corner_after;
            const float depth = quantize(tw_rng_range(r, 0.7f * bp->depth, bp->depth), 0.5f);
            const float h = pick_height(r, bp->side_h);
            struct building_spec sp;
            spec_init(&sp, r, widths[i], depth, h, pick_style(r, h, bp->tall_style_from),
                      (before ? 1u << 3 : 0u) | (after ? 1u << 1 : 0u), false);
            float m[12];
            side_transform(c, k, a, m);
            err = push_lot(c, &sp, m, c->mat_facade[tw_rng_below(r, FACADE_COLOURS)]);
        }
        a += widths[i];
    }
    return err;
}

/* Corner buildings and the sides between them. */
static int layout_perimeter(struct city *c, struct tw_rng *r, const struct block_params *bp)
{
    const float block = c->w - 2.0f * c->half_street;
    bool corner[4];
    for (uint32_t k = 0; k < 4; k++)
        corner[k] = (bp->side_mask >> k & 1u) && (bp->side_mask >> ((k + 3) % 4) & 1u);

    int err = TW_OK;
    for (uint32_t k = 0; k < 4 && !err; k++) {
        if (!(bp->side_mask >> k & 1u))
            continue;
        const float start = corner[k] ? bp->corner_size[k] : 0.0f;
        const float end = block - (corner[(k + 1) % 4] ? bp->corner_size[(k + 1) % 4] : 0.0f);
        err = layout_side(c, r, bp, k, start, end, corner[k], corner[(k + 1) % 4]);
    }

    /* Corner k faces the streets of sides k and k - 1; its walls 1 and 2
     * back onto the neighbouring side lots. */
    struct building_spec shared;
    uint32_t shared_material = 0;
    bool have_shared = false;
    for (uint32_t k = 0; k < 4 && !err; k++) {
        if (!corner[k])
            continue;
        struct building_spec sp;
        uint32_t material;
        if (bp->share_corners && have_shared) {
            sp = shared;
            material = shared_material;
        } else {
            const float h = pick_height(r, bp->corner_h);
            const float size = bp->corner_size[k];
            spec_init(&sp, r, size, size, h, pick_style(r, h, bp->tall_style_from),
                      (1u << 1) | (1u << 2), true);
            material = c->mat_facade[tw_rng_below(r, FACADE_COLOURS)];
            shared = sp;
            shared_material = material;
            have_shared = true;
        }
        float m[12];
        side_transform(c, k, 0.0f, m);
        err = push_lot(c, &sp, m, material);
    }
    return err;
}

static int add_instance(struct city *c, uint32_t proto, uint32_t mesh, uint32_t material,
                        const float m[12])
{
    if (mesh == no_mesh)
        return TW_OK;
    const int k = tw_tileset_add_instance(c->ts, proto, mesh, material, m);
    return k < 0 ? k : TW_OK;
}

/* Fits the window spacing of all pending lots to a triangle budget, then
 * instantiates them. Triangles fall roughly as 1 / bay, so a few
 * multiplicative corrections converge. */
static int place_lots(struct city *c, uint32_t proto, uint64_t fixed_triangles, float target)
{
    const float building_target = fmaxf(target - (float)fixed_triangles, 2000.0f);
    for (int pass = 0; pass < 2; pass++) {
        float scale = 1.0f, ratio = 0.0f;
        for (int iter = 0; iter < 12; iter++) {
            uint64_t total = 0;
            for (uint32_t k = 0; k < c->lot_count; k++) {
                struct building_spec *sp = &c->lots[k].spec;
                sp->bay = clampf(quantize(sp->base_bay * scale, 0.05f), min_bay(sp->style), 30.0f);
                total += building_triangles(c, sp);
            }
            ratio = (float)total / building_target;
            if (total == 0 || (ratio > 0.93f && ratio < 1.07f))
                break;
            scale = clampf(scale * ratio, 0.3f, 20.0f);
        }
        /* Low, sparse blocks cannot reach the budget with windows alone
         * even at the narrowest spacing: give them balconies. */
        if (ratio > 0.93f)
            break;
        for (uint32_t k = 0; k < c->lot_count; k++) {
            struct building_spec *sp = &c->lots[k].spec;
            if (sp->style != STYLE_RIBBON)
                sp->balconies = true;
        }
    }
    int err = TW_OK;
    for (uint32_t k = 0; k < c->lot_count && !err; k++) {
        uint32_t mesh[3];
        err = building_meshes(c, &c->lots[k].spec, mesh);
        if (!err)
            err = add_instance(c, proto, mesh[0], c->lots[k].facade_material, c->lots[k].transform);
        if (!err)
            err = add_instance(c, proto, mesh[1], c->mat_glass, c->lots[k].transform);
        if (!err)
            err = add_instance(c, proto, mesh[2], c->mat_roof, c->lots[k].transform);
    }
    c->lot_count = 0;
    return err;
}

static uint64_t mesh_triangles(const struct city *c, uint32_t mesh)
{
    return c->ts->meshes[mesh].triangle_count;
}

/* Streets, sidewalks, lamps and the block's ground: the same in every
 * prototype. */
static int add_streets(struct city *c, uint32_t proto, uint32_t ground_material,
                       uint64_t *triangles)
{
    static const float identity[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    int err = add_instance(c, proto, c->mesh_asphalt, c->mat_asphalt, identity);
    if (!err)
        err = add_instance(c, proto, c->mesh_sidewalk, c->mat_sidewalk, identity);
    if (!err)
        err = add_instance(c, proto, c->mesh_markings, c->mat_marking, identity);
    if (!err)
        err = add_instance(c, proto, c->mesh_lot, ground_material, identity);
    *triangles += mesh_triangles(c, c->mesh_asphalt) + mesh_triangles(c, c->mesh_sidewalk) +
                  mesh_triangles(c, c->mesh_markings) + mesh_triangles(c, c->mesh_lot);
    for (uint32_t k = 0; k < 4 && !err; k++) {
        float m[12];
        turn_about_centre(c, k, m);
        err = add_instance(c, proto, c->mesh_lamps, c->mat_metal, m);
        *triangles += mesh_triangles(c, c->mesh_lamps);
    }
    return err;
}

static float proto_height_cap(const struct city *c)
{
    return c->set.max_height - kerb_height;
}

static int build_dense(struct city *c, uint32_t proto, struct tw_rng *r, bool tallest)
{
    const float block = c->w - 2.0f * c->half_street;
    const float cap = proto_height_cap(c);
    const float hp = tallest ? cap : fmaxf(16.0f, cap * tw_rng_range(r, 0.45f, 1.0f));
    struct block_params bp = {0};
    bp.side_mask = 0xf;
    const float k = c->lot_scale;
    bp.depth = quantize(clampf(k * tw_rng_range(r, 13.0f, 20.0f), 6.0f, block * 0.3f), 0.5f);
    bp.share_corners = tw_rng_chance(r, 0.35f);
    const float shared_size = quantize(bp.depth + k * tw_rng_range(r, 0.0f, 5.0f), 0.5f);
    for (int i = 0; i < 4; i++)
        bp.corner_size[i] = bp.share_corners ? shared_size
                                             : quantize(bp.depth + k * tw_rng_range(r, 0.0f, 5.0f), 0.5f);
    bp.lot_min = 8.0f * k;
    bp.lot_max = 17.0f * k;
    bp.gap_chance = 0.2f;
    bp.row_chance = 0.25f;
    bp.side_h[0] = fmaxf(10.0f, 0.25f * hp);
    bp.side_h[1] = fmaxf(bp.side_h[0], 0.65f * hp);
    bp.corner_h[0] = fmaxf(12.0f, 0.5f * hp);
    bp.corner_h[1] = fmaxf(bp.corner_h[0], 0.85f * hp);
    bp.tall_style_from = 36.0f;
    int err = layout_perimeter(c, r, &bp);

    /* A tower in the courtyard, when the block is deep enough for one. */
    /* Corner lots reach depth + 5 m into the block; keep 2 m clear of them. */
    const float room = block - 2.0f * (bp.depth + 5.0f * k) - 4.0f;
    if (!err && room >= 10.0f && (tallest || tw_rng_chance(r, 0.6f))) {
        const float size = quantize(fminf(k * tw_rng_range(r, 14.0f, 22.0f), room), 0.5f);
        const float range[2] = {0.85f * hp, hp};
        const float h = tallest ? hp : pick_height(r, range);
        struct building_spec sp;
        spec_init(&sp, r, size, size, h, pick_style(r, h, bp.tall_style_from), 0, true);
        float m[12];
        const float lo = 0.5f * (c->w - size);
        rect_transform(tw_rng_below(r, 4), size, size, lo, lo, m);
        err = push_lot(c, &sp, m, c->mat_facade[tw_rng_below(r, FACADE_COLOURS)]);
    }
    uint64_t fixed = 0;
    if (!err)
        err = add_streets(c, proto, c->mat_courtyard, &fixed);
    if (!err)
        err = place_lots(c, proto, fixed, tw_rng_range(r, 15000.0f, 34000.0f));
    return err;
}

/* The perimeter of low buildings that low-rise blocks and parks share:
 * lots from 10 m to depth_max deep (times the lot scale) on the sides of
 * side_mask, corners up to 3 m deeper, no tall styles. */
struct low_perimeter {
    uint32_t side_mask;
    float depth_max;
    float lot_min, lot_max;     /* times the lot scale */
    float gap_chance, row_chance;
    float side_top, corner_top; /* tallest side and corner buildings, under the cap */
};

static int layout_low_perimeter(struct city *c, struct tw_rng *r, const struct low_perimeter *lp,
                                struct block_params *out)
{
    const float block = c->w - 2.0f * c->half_street;
    struct block_params bp = {0};
    bp.side_mask = lp->side_mask;
    const float k = c->lot_scale;
    bp.depth = quantize(clampf(k * tw_rng_range(r, 10.0f, lp->depth_max), 6.0f, block * 0.3f), 0.5f);
    for (int i = 0; i < 4; i++)
        bp.corner_size[i] = quantize(bp.depth + k * tw_rng_range(r, 0.0f, 3.0f), 0.5f);
    bp.lot_min = lp->lot_min * k;
    bp.lot_max = lp->lot_max * k;
    bp.gap_chance = lp->gap_chance;
    bp.row_chance = lp->row_chance;
    /* Two floors at least: 9.5 m holds a ground floor, one more and the
     * parapet. */
    bp.side_h[0] = 9.5f;
    bp.side_h[1] = fminf(lp->side_top, proto_height_cap(c));
    bp.corner_h[0] = 10.0f;
    bp.corner_h[1] = fminf(lp->corner_top, proto_height_cap(c));
    bp.tall_style_from = 1e9f;
    *out = bp;
    return layout_perimeter(c, r, out);
}

static int build_lowrise(struct city *c, uint32_t proto, struct tw_rng *r)
{
    static const struct low_perimeter lowrise = {
        .side_mask = 0xf, .depth_max = 14.0f, .lot_min = 8.0f, .lot_max = 14.0f,
        .gap_chance = 0.35f, .row_chance = 0.4f, .side_top = 15.0f, .corner_top = 17.0f,
    };
    struct block_params bp;
    int err = layout_low_perimeter(c, r, &lowrise, &bp);
    uint64_t fixed = 0;
    if (!err)
        err = add_streets(c, proto, c->mat_courtyard, &fixed);
    if (!err)
        err = place_lots(c, proto, fixed, tw_rng_range(r, 12000.0f, 18000.0f));
    return err;
}

static int build_park_meshes(struct city *c);

/* A park: lawns, paths, a fountain and trees, with low buildings along two
 * sides (fewer would not carry the triangle budget). */
static int build_park(struct city *c, uint32_t proto, struct tw_rng *r)
{
    if (!c->park_meshes) {
        const int err = build_park_meshes(c);
        if (err)
            return err;
    }
    static const struct low_perimeter park = {
        .side_mask = (1u << 2) | (1u << 3), .depth_max = 13.0f, .lot_min = 7.0f,
        .lot_max = 12.0f, .gap_chance = 0.2f, .row_chance = 0.3f, .side_top = 18.0f,
        .corner_top = 20.0f,
    };
    struct block_params bp;
    int err = layout_low_perimeter(c, r, &park, &bp);
    const float k = c->lot_scale;

    uint64_t fixed = 0;
    if (!err)
        err = add_streets(c, proto, c->mat_grass, &fixed);
    static const float identity[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    if (!err)
        err = add_instance(c, proto, c->mesh_paths, c->mat_sidewalk, identity);
    if (!err)
        err = add_instance(c, proto, c->mesh_fountain, c->mat_sidewalk, identity);
    if (!err)
        err = add_instance(c, proto, c->mesh_water, c->mat_water, identity);
    fixed += mesh_triangles(c, c->mesh_paths) + mesh_triangles(c, c->mesh_fountain) +
             mesh_triangles(c, c->mesh_water);

    /* Trees on a jittered grid, off the paths, the fountain and the lots.
     * Canopies reach 3.3 m from the trunk: 3.5 m from the lot line keeps
     * them over the block. */
    const float lo = c->half_street + 3.5f, hi = c->w - c->half_street - 3.5f;
    const float centre = 0.5f * c->w, step = 8.5f * k;
    /* Corner lots reach 3 k m deeper than side lots. */
    const float built = c->half_street + bp.depth + 3.0f * k + 1.0f;
    /* Candidates first, then an even subset: the instance count stays
     * moderate while the trees spread over the whole lawn. */
    enum { MAX_CANDIDATES = 256, MAX_TREES = 12 };
    float candidates[MAX_CANDIDATES][4];
    uint32_t count = 0;
    const uint32_t steps = (uint32_t)floorf((hi - lo) / step) + 1;
    for (uint32_t j = 0; j < steps; j++) {
        for (uint32_t i = 0; i < steps && count < MAX_CANDIDATES; i++) {
            const float tx = clampf(lo + step * (float)i + tw_rng_range(r, -1.5f, 1.5f), lo, hi);
            const float tz = clampf(lo + step * (float)j + tw_rng_range(r, -1.5f, 1.5f), lo, hi);
            const float angle = tw_rng_range(r, 0.0f, 6.2831853f);
            const float scale = tw_rng_range(r, 0.8f, 1.2f);
            if (fabsf(tx - centre) < 3.5f || fabsf(tz - centre) < 3.5f)
                continue;
            if (((bp.side_mask >> 2 & 1u) && tz > c->w - built) ||
                ((bp.side_mask >> 3 & 1u) && tx < built))
                continue;
            const float cand[4] = {tx, tz, angle, scale};
            memcpy(candidates[count++], cand, sizeof(cand));
        }
    }
    const uint32_t trees = count < MAX_TREES ? count : MAX_TREES;
    for (uint32_t t = 0; t < trees && !err; t++) {
        const float *cand = candidates[(uint64_t)t * count / trees];
        const float co = cand[3] * cosf(cand[2]), si = cand[3] * sinf(cand[2]);
        const float m[12] = {co, 0.0f, si, cand[0], 0.0f, cand[3], 0.0f, kerb_height,
                             -si, 0.0f, co, cand[1]};
        err = add_instance(c, proto, c->mesh_trunk, c->mat_bark, m);
        if (!err)
            err = add_instance(c, proto, c->mesh_canopy, c->mat_foliage, m);
        fixed += mesh_triangles(c, c->mesh_trunk) + mesh_triangles(c, c->mesh_canopy);
    }
    if (!err)
        err = place_lots(c, proto, fixed, tw_rng_range(r, 11500.0f, 16000.0f));
    return err;
}

/* ---- shared meshes ---------------------------------------------------------------- */

static int finish_shared(struct city *c, uint32_t *mesh)
{
    if (c->wall.err)
        return c->wall.err;
    const int index = tw_tileset_add_mesh(c->ts, c->wall.positions, c->wall.normals,
                                          c->wall.vertex_count, c->wall.indices,
                                          c->wall.triangle_count);
    if (index < 0)
        return index;
    *mesh = (uint32_t)index;
    return TW_OK;
}

/* An axis-aligned horizontal rectangle of side 0, repeated on all four
 * sides by turns about the tile's centre. */
static void emit_ground_rect4(struct city *c, float x0, float z0, float x1, float z1, float y)
{
    const float up[3] = {0, 1, 0};
    for (uint32_t k = 0; k < 4; k++) {
        float p[4][3];
        turn_point(c, k, x0, y, z0, p[0]);
        turn_point(c, k, x1, y, z0, p[1]);
        turn_point(c, k, x1, y, z1, p[2]);
        turn_point(c, k, x0, y, z1, p[3]);
        emit_polygon(&c->wall, (const float(*)[3])p, 4, up);
    }
}

static int build_ground_meshes(struct city *c)
{
    const float w = c->w, s = c->half_street, r = c->kerb_line;
    int err;

    /* Asphalt, sidewalk and lot ground as pinwheels: no overlaps. */
    tw_mesh_builder_reset(&c->wall, false);
    emit_ground_rect4(c, 0.0f, 0.0f, w - r, r, 0.0f);
    if ((err = finish_shared(c, &c->mesh_asphalt)))
        return err;

    tw_mesh_builder_reset(&c->wall, false);
    emit_ground_rect4(c, r, r, w - s, s, kerb_height);
    for (uint32_t k = 0; k < 4; k++) {
        float p[4][3];
        turn_point(c, k, r, 0.0f, r, p[0]);
        turn_point(c, k, w - r, 0.0f, r, p[1]);
        turn_point(c, k, w - r, kerb_height, r, p[2]);
        turn_point(c, k, r, kerb_height, r, p[3]);
        /* The kerb faces the road: side 0's -z, turned. */
        const float facing[3] = {-turn_sin[k], 0.0f, -turn_cos[k]};
        emit_polygon(&c->wall, (const float(*)[3])p, 4, facing);
    }
    if ((err = finish_shared(c, &c->mesh_sidewalk)))
        return err;

    tw_mesh_builder_reset(&c->wall, false);
    {
        const float up[3] = {0, 1, 0};
        const float p0[3] = {s, kerb_height, s}, p1[3] = {w - s, kerb_height, s};
        const float p2[3] = {w - s, kerb_height, w - s}, p3[3] = {s, kerb_height, w - s};
        emit_quad(&c->wall, p0, p1, p2, p3, up);
    }
    if ((err = finish_shared(c, &c->mesh_lot)))
        return err;

    /* Markings: half of each centre line and zebra crossing lies in each
     * tile, symmetric about the border, so neighbours complete them. */
    tw_mesh_builder_reset(&c->wall, false);
    const float y = 0.01f, half_line = 0.06f;
    const float cross0 = s + 0.8f, cross1 = s + 3.8f;
    for (float z = 0.25f; z + 0.5f <= r - 0.2f; z += 1.0f) {
        emit_ground_rect4(c, cross0, z, cross1, z + 0.5f, y);
        emit_ground_rect4(c, w - cross1, z, w - cross0, z + 0.5f, y);
    }
    const float dash_lo = cross1 + 1.0f, dash_hi = w - cross1 - 1.0f;
    for (float x = 0.5f * w - 1.5f; x >= dash_lo; x -= 6.0f)
        emit_ground_rect4(c, x, 0.0f, x + 3.0f, half_line, y);
    for (float x = 0.5f * w + 4.5f; x + 3.0f <= dash_hi; x += 6.0f)
        emit_ground_rect4(c, x, 0.0f, x + 3.0f, half_line, y);
    if ((err = finish_shared(c, &c->mesh_markings)))
        return err;

    /* Lamps on the building side of the sidewalk of side 0, clear of the
     * street band (which ends 1 m short of the lot line). */
    tw_mesh_builder_reset(&c->wall, false);
    const float lz = s - 0.55f;
    const float span = w - 2.0f * s - 4.0f;
    const uint32_t lamps = (uint32_t)fmaxf(2.0f, floorf(span / 18.0f + 0.5f) + 1.0f);
    for (uint32_t i = 0; i < lamps; i++) {
        const float lx = s + 2.0f + span * (float)i / (float)(lamps - 1);
        const float base_lo[3] = {lx - 0.15f, kerb_height, lz - 0.15f};
        const float base_hi[3] = {lx + 0.15f, kerb_height + 0.6f, lz + 0.15f};
        const float pole_lo[3] = {lx - 0.07f, kerb_height + 0.6f, lz - 0.07f};
        const float pole_hi[3] = {lx + 0.07f, kerb_height + 6.0f, lz + 0.07f};
        const float head_lo[3] = {lx - 0.3f, kerb_height + 6.0f, lz - 0.22f};
        const float head_hi[3] = {lx + 0.3f, kerb_height + 6.25f, lz + 0.22f};
        emit_box(&c->wall, base_lo, base_hi, FACES_NO_BOTTOM);
        emit_box(&c->wall, pole_lo, pole_hi, FACES_SIDES);
        emit_box(&c->wall, head_lo, head_hi, FACES_SIDES | FACE_PY | FACE_NY);
    }
    if ((err = finish_shared(c, &c->mesh_lamps)))
        return err;
    return TW_OK;
}

/* A canopy blob: an ellipsoid of radius about centre (tw_icosphere_each). */
struct blob {
    struct tw_mesh_builder *b;
    const float *centre, *radius;
};

static void blob_triangle(void *user, const float v[3][3], const float len[3])
{
    const struct blob *bl = user;
    float p[3][3];
    float facing[3] = {0, 0, 0};
    for (int k = 0; k < 3; k++) {
        for (int d = 0; d < 3; d++)
            p[k][d] = bl->centre[d] + bl->radius[d] * v[k][d] / len[k];
        for (int d = 0; d < 3; d++)
            facing[d] += (p[k][d] - bl->centre[d]) / bl->radius[d];
    }
    emit_polygon(bl->b, (const float(*)[3])p, 3, facing);
}

/* An icosahedron with every face split into n x n triangles, pushed onto an
 * ellipsoid: a canopy blob of 20 n^2 triangles. */
static void emit_blob(struct tw_mesh_builder *b, const float centre[3], const float radius[3],
                      uint32_t n)
{
    struct blob bl = {b, centre, radius};
    tw_icosphere_each(n, blob_triangle, &bl);
}

static int build_park_meshes(struct city *c)
{
    int err;
    tw_mesh_builder_reset(&c->wall, false);
    const float blob_a[3] = {0.0f, 5.4f, 0.0f}, radius_a[3] = {2.6f, 2.1f, 2.6f};
    const float blob_b[3] = {0.5f, 6.9f, -0.3f}, radius_b[3] = {1.8f, 1.5f, 1.8f};
    emit_blob(&c->wall, blob_a, radius_a, 4);
    emit_blob(&c->wall, blob_b, radius_b, 2);
    if ((err = finish_shared(c, &c->mesh_canopy)))
        return err;

    tw_mesh_builder_reset(&c->wall, false);
    emit_prism(&c->wall, 0.0f, 0.0f, 0.22f, 0.0f, 4.6f, 6, false);
    if ((err = finish_shared(c, &c->mesh_trunk)))
        return err;

    /* A cross of paths, slightly above the lawn. */
    tw_mesh_builder_reset(&c->wall, false);
    const float s = c->half_street, w = c->w, m = 0.5f * c->w, y = kerb_height + 0.02f;
    const float rects[3][4] = {
        {s, m - 1.5f, w - s, m + 1.5f}, {m - 1.5f, s, m + 1.5f, m - 1.5f},
        {m - 1.5f, m + 1.5f, m + 1.5f, w - s},
    };
    const float up[3] = {0, 1, 0};
    for (int k = 0; k < 3; k++) {
        const float p0[3] = {rects[k][0], y, rects[k][1]}, p1[3] = {rects[k][2], y, rects[k][1]};
        const float p2[3] = {rects[k][2], y, rects[k][3]}, p3[3] = {rects[k][0], y, rects[k][3]};
        emit_quad(&c->wall, p0, p1, p2, p3, up);
    }
    if ((err = finish_shared(c, &c->mesh_paths)))
        return err;

    /* The fountain: a ring wall (outer and inner faces, top) and a column. */
    tw_mesh_builder_reset(&c->wall, false);
    const uint32_t sides = 16;
    const float r_out = 4.0f, r_in = 3.6f, y0 = kerb_height, y1 = kerb_height + 0.6f;
    for (uint32_t k = 0; k < sides; k++) {
        const double a0 = 2.0 * 3.14159265358979323846 * k / sides;
        const double a1 = 2.0 * 3.14159265358979323846 * (k + 1) / sides;
        const float c0 = (float)cos(a0), s0 = (float)sin(a0), c1 = (float)cos(a1), s1 = (float)sin(a1);
        const float out[3] = {c0 + c1, 0.0f, s0 + s1}, in[3] = {-out[0], 0.0f, -out[2]};
        const float o0[3] = {m + r_out * c0, y0, m + r_out * s0}, o1[3] = {m + r_out * c1, y0, m + r_out * s1};
        const float o2[3] = {m + r_out * c1, y1, m + r_out * s1}, o3[3] = {m + r_out * c0, y1, m + r_out * s0};
        const float i0[3] = {m + r_in * c0, y0, m + r_in * s0}, i1[3] = {m + r_in * c1, y0, m + r_in * s1};
        const float i2[3] = {m + r_in * c1, y1, m + r_in * s1}, i3[3] = {m + r_in * c0, y1, m + r_in * s0};
        emit_quad(&c->wall, o0, o1, o2, o3, out);
        emit_quad(&c->wall, i0, i1, i2, i3, in);
        emit_quad(&c->wall, o3, o2, i2, i3, up);
    }
    emit_prism(&c->wall, m, m, 0.35f, y0, y0 + 2.2f, 8, true);
    if ((err = finish_shared(c, &c->mesh_fountain)))
        return err;

    tw_mesh_builder_reset(&c->wall, false);
    float disc[16][3];
    for (uint32_t k = 0; k < sides; k++) {
        const double a = 2.0 * 3.14159265358979323846 * k / sides;
        disc[k][0] = m + r_in * (float)cos(a);
        disc[k][1] = kerb_height + 0.4f;
        disc[k][2] = m + r_in * (float)sin(a);
    }
    emit_polygon(&c->wall, (const float(*)[3])disc, sides, up);
    if ((err = finish_shared(c, &c->mesh_water)))
        return err;
    c->park_meshes = true;
    return TW_OK;
}

static int add_materials(struct city *c)
{
    static const float colours[11][4] = {
        {0.16f, 0.16f, 0.17f, 1.0f},  /* asphalt */
        {0.62f, 0.60f, 0.56f, 1.0f},  /* sidewalk */
        {0.88f, 0.88f, 0.82f, 1.0f},  /* road marking */
        {0.44f, 0.42f, 0.39f, 1.0f},  /* courtyard paving */
        {0.26f, 0.46f, 0.19f, 1.0f},  /* grass */
        {0.09f, 0.13f, 0.19f, 1.0f},  /* window glass */
        {0.32f, 0.29f, 0.28f, 1.0f},  /* roof */
        {0.20f, 0.21f, 0.23f, 1.0f},  /* lamp metal */
        {0.17f, 0.37f, 0.13f, 1.0f},  /* foliage */
        {0.36f, 0.26f, 0.17f, 1.0f},  /* bark */
        {0.22f, 0.38f, 0.50f, 1.0f},  /* water */
    };
    static const float facades[FACADE_COLOURS][4] = {
        {0.56f, 0.27f, 0.20f, 1.0f},  /* brick */
        {0.77f, 0.68f, 0.52f, 1.0f},  /* sandstone */
        {0.63f, 0.63f, 0.61f, 1.0f},  /* concrete */
        {0.86f, 0.81f, 0.70f, 1.0f},  /* cream render */
        {0.42f, 0.47f, 0.53f, 1.0f},  /* blue-grey panels */
        {0.73f, 0.53f, 0.31f, 1.0f},  /* ochre */
    };
    uint32_t *slots[11] = {
        &c->mat_asphalt, &c->mat_sidewalk, &c->mat_marking, &c->mat_courtyard,
        &c->mat_grass, &c->mat_glass, &c->mat_roof, &c->mat_metal, &c->mat_foliage,
        &c->mat_bark, &c->mat_water,
    };
    for (int k = 0; k < 11; k++) {
        const int m = tw_tileset_add_material(c->ts, colours[k]);
        if (m < 0)
            return m;
        *slots[k] = (uint32_t)m;
    }
    for (int k = 0; k < FACADE_COLOURS; k++) {
        const int m = tw_tileset_add_material(c->ts, facades[k]);
        if (m < 0)
            return m;
        c->mat_facade[k] = (uint32_t)m;
    }
    return TW_OK;
}

/* ---- the generator's lifetime (tilesets-private.h) --------------------------------- */

/* Sets up the generator on an unfinished tileset: materials, then the
 * ground and park meshes that every prototype shares (the park meshes later,
 * with the first park, unless park_meshes_now). */
static int city_begin(struct city *c, struct tw_tileset *ts, const struct tw_city_settings *set,
                      bool park_meshes_now)
{
    memset(c, 0, sizeof(*c));
    c->ts = ts;
    c->set = *set;
    c->w = c->set.footprint;
    c->half_street = 0.5f * c->set.street_width;
    c->kerb_line = c->half_street - clampf(0.22f * c->set.street_width, 1.5f, 4.0f);
    c->lot_scale = fmaxf(1.0f, (c->w - c->set.street_width) / 66.0f);
    int err = add_materials(c);
    if (!err)
        err = build_ground_meshes(c);
    if (!err && park_meshes_now)
        err = build_park_meshes(c);
    return err;
}

static void city_release(struct city *c)
{
    tw_mesh_builder_release(&c->wall);
    tw_mesh_builder_release(&c->glass);
    tw_mesh_builder_release(&c->roof);
    free(c->cache);
    free(c->lots);
    c->cache = NULL;
    c->lots = NULL;
}

static int city_add_block(struct city *c, uint32_t proto, enum block_kind kind, uint64_t stream,
                          bool tallest)
{
    struct tw_rng r = {stream};
    switch (kind) {
    case BLOCK_DENSE: return build_dense(c, proto, &r, tallest);
    case BLOCK_LOWRISE: return build_lowrise(c, proto, &r);
    default: return build_park(c, proto, &r);
    }
}

struct tw_city_blocks {
    struct city city;
};

static int blocks_create(struct tw_tileset *ts, const struct tw_city_settings *settings,
                         bool park_meshes_now, struct tw_city_blocks **out)
{
    if (!ts || !settings || !out || ts->finished)
        return TW_ERR_INVALID;
    *out = NULL;
    struct tw_city_blocks *b = malloc(sizeof(*b));
    if (!b)
        return TW_ERR_NOMEM;
    const int err = city_begin(&b->city, ts, settings, park_meshes_now);
    if (err) {
        tw_city_blocks_destroy(b);
        return err;
    }
    *out = b;
    return TW_OK;
}

int tw_city_blocks_create(struct tw_tileset *ts, const struct tw_city_settings *settings,
                          struct tw_city_blocks **out)
{
    return blocks_create(ts, settings, true, out);
}

int tw_city_blocks_create_tile(struct tw_tileset *ts, const struct tw_city_settings *settings,
                               struct tw_city_blocks **out)
{
    return blocks_create(ts, settings, false, out);
}

/* Every height a block draws is at most proto_height_cap() before it is
 * rounded to height_step (build_dense(): hp <= cap; the other kinds cap
 * lower), so at most cap + height_step / 2 after; spec_init() keeps a
 * building's top, roof clutter and parapet included, 0.01 m under its
 * height; it stands on the kerb. Lamps (6.4 m) and park trees (10.3 m) stay
 * under the lowest max_height (20 m). */
float tw_city_blocks_max_top(const struct tw_city_settings *settings)
{
    return settings->max_height + 0.5f * height_step;
}

void tw_city_blocks_destroy(struct tw_city_blocks *blocks)
{
    if (!blocks)
        return;
    city_release(&blocks->city);
    free(blocks);
}

int tw_city_blocks_add(struct tw_city_blocks *blocks, uint32_t proto,
                       enum tw_city_block_kind kind, uint64_t stream, bool tallest)
{
    if (!blocks || proto >= blocks->city.ts->prototype_count)
        return TW_ERR_INVALID;
    const enum block_kind k = kind == TW_CITY_BLOCK_DENSE     ? BLOCK_DENSE
                              : kind == TW_CITY_BLOCK_LOWRISE ? BLOCK_LOWRISE
                                                              : BLOCK_PARK;
    return city_add_block(&blocks->city, proto, k, stream, tallest);
}

int tw_city_blocks_add_streets(struct tw_city_blocks *blocks, uint32_t proto,
                               uint32_t ground_material)
{
    if (!blocks || proto >= blocks->city.ts->prototype_count ||
        ground_material >= blocks->city.ts->material_count)
        return TW_ERR_INVALID;
    uint64_t triangles = 0;
    return add_streets(&blocks->city, proto, ground_material, &triangles);
}

void tw_city_blocks_lot_area(const struct tw_city_blocks *blocks, float area[4], float *ground_y)
{
    const struct city *c = &blocks->city;
    area[0] = area[1] = c->half_street;
    area[2] = area[3] = c->w - c->half_street;
    *ground_y = kerb_height;
}

/* ---- public API -------------------------------------------------------------------- */

void tw_tilesets_city_default_settings(struct tw_city_settings *s)
{
    if (!s)
        return;
    s->prototypes = 12;
    s->footprint = 80.0f;
    s->street_width = 14.0f;
    s->max_height = 90.0f;
    s->max_cluster_triangles = 2048;
}

int tw_city_settings_resolve(const struct tw_city_settings *in, struct tw_city_settings *out,
                             const struct tw_log *log, const char *who)
{
    struct tw_city_settings d;
    tw_tilesets_city_default_settings(&d);
    *out = d;
    if (in) {
        if (in->prototypes)
            out->prototypes = in->prototypes;
        if (in->footprint != 0.0f)
            out->footprint = in->footprint;
        if (in->street_width != 0.0f)
            out->street_width = in->street_width;
        if (in->max_height != 0.0f)
            out->max_height = in->max_height;
        if (in->max_cluster_triangles)
            out->max_cluster_triangles = in->max_cluster_triangles;
    }
    if (!tw_procedural_prototypes_valid(out->prototypes, log, who))
        return TW_ERR_INVALID;
    if (!isfinite(out->street_width) || !(out->street_width >= 4.0f)) {
        tw_log_printf(log, TW_LOG_ERROR,
                      "tilesets: %s: street_width = %g m, must be at least 4 m (caller's settings)",
                      who, (double)out->street_width);
        return TW_ERR_INVALID;
    }
    if (!isfinite(out->footprint) || !(out->footprint - out->street_width >= 40.0f) ||
        !(out->footprint <= 1000.0f)) {
        tw_log_printf(log, TW_LOG_ERROR,
                      "tilesets: %s: footprint = %g m with street_width = %g m: the block "
                      "(footprint - street_width) must be at least 40 m and the footprint at "
                      "most 1000 m (caller's settings)",
                      who, (double)out->footprint, (double)out->street_width);
        return TW_ERR_INVALID;
    }
    if (!tw_procedural_in_range(out->max_height, 20.0f, 1000.0f, "max_height", " m", log,
                                who))
        return TW_ERR_INVALID;
    return TW_OK;
}

int tw_tilesets_city(uint64_t seed, const struct tw_city_settings *settings,
                     const struct tw_log *log, struct tw_tileset **out)
{
    if (!tw_procedural_out_given(out, log, "city"))
        return TW_ERR_INVALID;
    *out = NULL;
    struct tw_city_settings set;
    int err = tw_city_settings_resolve(settings, &set, log, "city");
    if (err)
        return err;
    struct city c;
    memset(&c, 0, sizeof(c));

    struct tw_tileset *ts = NULL;
    err = tw_tileset_create("city", set.footprint, set.footprint, &ts);
    if (err)
        goto out;
    if ((err = city_begin(&c, ts, &set, true)))
        goto out;

    const uint32_t n = set.prototypes;
    for (uint32_t k = 0; k < n; k++) {
        /* The last prototype is a park, the one before a low-rise block;
         * prototype 0 holds the tallest tower. */
        const enum block_kind kind = k == n - 1 ? BLOCK_PARK : k == n - 2 ? BLOCK_LOWRISE : BLOCK_DENSE;
        static const char *const kind_names[] = {"dense", "lowrise", "park"};
        static const float weights[] = {1.0f, 0.6f, 0.4f};
        char name[48];
        snprintf(name, sizeof(name), "city-%s-%02u", kind_names[kind], k);
        const int proto = tw_tileset_add_prototype(ts, name, weights[kind]);
        if (proto < 0) {
            err = proto;
            goto out;
        }
        const uint64_t stream = tw_tiles_hash(seed, (int64_t)k, 0x63697479);
        if ((err = city_add_block(&c, (uint32_t)proto, kind, stream, k == 0)))
            goto out;
    }
out:
    err = tw_procedural_hand_over(ts, err, set.max_cluster_triangles, log, "city", out);
    city_release(&c);
    return err;
}
