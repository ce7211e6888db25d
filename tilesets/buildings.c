/* The city's buildings (buildings.h): facades of windows, ledges, sills and
 * balconies on one or two tiers, roofs with their clutter, and the meshes
 * of a tileset's buildings, shared by equal specs. */
#include "tilesets/buildings.h"
#include "tilesets/shapes.h"
#include "tiles/array.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

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
    tw_shape_polygon(b, (const float(*)[3])p, 4, facing);
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

enum roof_feature {
    ROOF_PLAIN,
    ROOF_PENTHOUSE,
    ROOF_TANK,
};

static bool spec_equal(const struct tw_building_spec *a, const struct tw_building_spec *b)
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
static float roof_extra(const struct tw_building_spec *sp)
{
    const float clutter = sp->roof == ROOF_PENTHOUSE ? 3.4f : sp->roof == ROOF_TANK ? 3.0f : 1.4f;
    return fmaxf(clutter, sp->parapet_h);
}

float tw_building_min_bay(uint32_t style)
{
    return style == TW_FACADE_RIBBON ? 1.1f : style == TW_FACADE_CLASSIC ? 1.9f : 1.7f;
}

uint32_t tw_building_party_walls(float height, uint32_t blank_mask)
{
    return height <= 32.0f ? blank_mask : 0u;
}

void tw_building_spec_init(struct tw_building_spec *sp, struct tw_rng *r, float w, float d,
                           float height, uint32_t style, uint32_t blank_mask,
                           bool allow_setback)
{
    memset(sp, 0, sizeof(*sp));
    sp->w = w;
    sp->d = d;
    sp->style = style;
    sp->blank_mask = tw_building_party_walls(height, blank_mask);
    sp->floor_h = tw_quantize(tw_rng_range(r, 3.1f, 3.6f), 0.1f);
    sp->ground_h = tw_quantize(tw_rng_range(r, 3.9f, 4.8f), 0.1f);
    sp->parapet_h = tw_quantize(tw_rng_range(r, 0.6f, 1.2f), 0.1f);
    switch (style) {
    case TW_FACADE_CLASSIC:
        sp->recess = tw_quantize(tw_rng_range(r, 0.2f, 0.35f), 0.05f);
        sp->window_ratio = tw_quantize(tw_rng_range(r, 0.42f, 0.55f), 0.05f);
        sp->base_bay = tw_quantize(tw_rng_range(r, 2.6f, 3.4f), 0.1f);
        sp->ledge_every = 2 + tw_rng_below(r, 3);
        break;
    case TW_FACADE_MODERN:
        sp->recess = tw_quantize(tw_rng_range(r, 0.15f, 0.3f), 0.05f);
        sp->window_ratio = tw_quantize(tw_rng_range(r, 0.5f, 0.7f), 0.05f);
        sp->base_bay = tw_quantize(tw_rng_range(r, 2.8f, 3.8f), 0.1f);
        sp->ledge_every = tw_rng_chance(r, 0.5f) ? 0 : 4 + tw_rng_below(r, 3);
        break;
    default:
        sp->recess = 0.15f;
        sp->window_ratio = 1.0f;
        sp->base_bay = tw_quantize(tw_rng_range(r, 1.4f, 2.2f), 0.1f);
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
        sp->inset = tw_quantize(tw_rng_range(r, 2.0f, fminf(w, d) * 0.2f), 0.5f);
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

static float floor_height(const struct tw_building_spec *sp, const struct tier *t, uint32_t i)
{
    return t->ground && i == 0 ? sp->ground_h : sp->floor_h;
}

static float tier_top(const struct tw_building_spec *sp, const struct tier *t)
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
                      const struct tw_building_spec *sp, const struct tier *t,
                      const struct facade *f, bool blank)
{
    const float top = tier_top(sp, t);
    const float margin = sp->style == TW_FACADE_RIBBON ? 0.4f : 0.5f;
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
            if (sp->style == TW_FACADE_RIBBON) {
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
                    if (sp->style == TW_FACADE_CLASSIC && !shop) {
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
                              const struct tw_building_spec *sp, const struct tier *t, float top)
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
        tw_shape_box(wall, lo, hi, TW_FACES_SIDES);
        tw_shape_box(roof, lo, hi, TW_FACE_PY);
        taken[0] = px; taken[1] = pz; taken[2] = px + pw; taken[3] = pz + pd;
        has_taken = true;
    } else if (sp->roof == ROOF_TANK) {
        const float radius = fminf(1.4f, 0.25f * fminf(aw, ad));
        const float cx = ax + radius + (aw - 2.0f * radius) * tw_rng_float(&r);
        const float cz = az + radius + (ad - 2.0f * radius) * tw_rng_float(&r);
        const float lo[3] = {cx - radius, top, cz - radius};
        const float hi[3] = {cx + radius, top + 0.8f, cz + radius};
        tw_shape_box(roof, lo, hi, TW_FACES_NO_BOTTOM);
        tw_shape_prism(roof, cx, cz, radius, top + 0.8f, top + 3.0f, 8, true);
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
            tw_shape_box(roof, lo, hi, TW_FACES_NO_BOTTOM);
            break;
        }
    }
}

/* The whole building, in mesh-local coordinates: footprint [0, w] x [0, d],
 * ground at y = 0. */
static void emit_building(struct tw_mesh_builder *wall, struct tw_mesh_builder *glass,
                          struct tw_mesh_builder *roof, const struct tw_building_spec *sp)
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
                tw_shape_quad(roof, p0, p1, p2, p3, up);
            }
        } else {
            const float p0[3] = {t->x0, top, t->z0}, p1[3] = {t->x1, top, t->z0};
            const float p2[3] = {t->x1, top, t->z1}, p3[3] = {t->x0, top, t->z1};
            tw_shape_quad(roof, p0, p1, p2, p3, up);
            emit_roof_clutter(wall, roof, sp, t, top);
        }
    }
}
/* ---- the buildings of a tileset ----------------------------------------------------- */

static const uint32_t no_mesh = UINT32_MAX;

struct tw_cached_building {
    struct tw_building_spec spec;
    uint32_t mesh[3];       /* wall, glass, roof; no_mesh when empty */
};

void tw_buildings_init(struct tw_buildings *b, struct tw_tileset *ts)
{
    memset(b, 0, sizeof(*b));
    b->ts = ts;
}

void tw_buildings_finish(struct tw_buildings *b)
{
    tw_mesh_builder_release(&b->wall);
    tw_mesh_builder_release(&b->glass);
    tw_mesh_builder_release(&b->roof);
    free(b->cache);
    b->cache = NULL;
    b->cache_count = b->cache_cap = 0;
}

static int add_mesh_from(struct tw_buildings *bs, struct tw_mesh_builder *b, uint32_t *mesh)
{
    if (!b->err && b->triangle_count == 0) {
        *mesh = no_mesh;
        return TW_OK;
    }
    return tw_mesh_builder_add_to(b, bs->ts, mesh);
}

uint64_t tw_buildings_triangles(struct tw_buildings *b, const struct tw_building_spec *sp)
{
    tw_mesh_builder_reset(&b->wall, true);
    tw_mesh_builder_reset(&b->glass, true);
    tw_mesh_builder_reset(&b->roof, true);
    emit_building(&b->wall, &b->glass, &b->roof, sp);
    return (uint64_t)b->wall.triangle_count + b->glass.triangle_count + b->roof.triangle_count;
}

/* The meshes of a building, generated on first use. */
static int building_meshes(struct tw_buildings *b, const struct tw_building_spec *sp,
                           uint32_t mesh[3])
{
    for (uint32_t k = 0; k < b->cache_count; k++) {
        if (spec_equal(&b->cache[k].spec, sp)) {
            memcpy(mesh, b->cache[k].mesh, sizeof(b->cache[k].mesh));
            return TW_OK;
        }
    }
    int err = tw_array_reserve_u32((void **)&b->cache, &b->cache_cap, b->cache_count + 1,
                                   sizeof(*b->cache), 64);
    if (err)
        return err;
    tw_mesh_builder_reset(&b->wall, false);
    tw_mesh_builder_reset(&b->glass, false);
    tw_mesh_builder_reset(&b->roof, false);
    emit_building(&b->wall, &b->glass, &b->roof, sp);
    struct tw_cached_building *entry = &b->cache[b->cache_count];
    entry->spec = *sp;
    err = add_mesh_from(b, &b->wall, &entry->mesh[0]);
    if (!err)
        err = add_mesh_from(b, &b->glass, &entry->mesh[1]);
    if (!err)
        err = add_mesh_from(b, &b->roof, &entry->mesh[2]);
    if (err)
        return err;
    b->cache_count++;
    memcpy(mesh, entry->mesh, sizeof(entry->mesh));
    return TW_OK;
}

int tw_buildings_place(struct tw_buildings *b, uint32_t proto, const struct tw_building_spec *sp,
                       const float transform[12], const uint32_t material[3])
{
    uint32_t mesh[3];
    int err = building_meshes(b, sp, mesh);
    for (int k = 0; k < 3 && !err; k++) {
        if (mesh[k] == no_mesh)
            continue;
        const int index = tw_tileset_add_instance(b->ts, proto, mesh[k], material[k], transform);
        err = index < 0 ? index : TW_OK;
    }
    return err;
}
