/* glTF import, base colour textures and vertex colours (gltf-private.h).
 * The renderer draws one colour per instance: a primitive whose base colour
 * varies (a baseColorTexture, COLOR_0) is split by colour into one primitive
 * per distinct colour, each triangle taking the texel at its centroid's UV
 * (nearest) times its mean vertex colour times the material's factor. A
 * texture that cannot be used costs a warning, never the import. */
#include "tiles/tiles-internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tilesets/gltf-private.h"

#define MAX_SPLIT_COLOURS 64

enum {
    WRAP_REPEAT = 10497,
    WRAP_CLAMP_TO_EDGE = 33071,
    WRAP_MIRRORED_REPEAT = 33648,
};

/* The usable baseColorTexture of material index, resolved (and warned about)
 * once per import; NULL if none. */
static const struct tw_gltf_material_texture *material_texture(struct tw_gltf_importer *im,
                                                               uint32_t index)
{
    struct tw_gltf_material_texture *mt = &im->material_textures[index];
    if (mt->state)
        return mt->state > 0 ? mt : NULL;
    mt->state = -1;
    const struct tw_gltf_doc *d = im->doc;
    const struct tw_gltf_doc_material *mat = &d->materials[index];
    const int32_t t = mat->base_color_texture;
    if (t < 0)
        return NULL;
    if ((uint32_t)t >= d->texture_count) {
        tw_gltf_warn_texture(
            im,
            "materials[%u].pbrMetallicRoughness.baseColorTexture: %d is not a texture "
            "(%u); using the base colour factor",
            index, t, d->texture_count);
        return NULL;
    }
    if (mat->base_color_texcoord < 0 || mat->base_color_texcoord > 99) {
        tw_gltf_warn_texture(
            im,
            "materials[%u].pbrMetallicRoughness.baseColorTexture.texCoord: %d is not "
            "valid; using the base colour factor",
            index, mat->base_color_texcoord);
        return NULL;
    }
    const struct tw_gltf_doc_texture *tex = &d->textures[t];
    if (tex->source < 0 || (uint32_t)tex->source >= d->image_count) {
        tw_gltf_warn_texture(
            im, "textures[%d].source: %d is not an image (%u); using the base colour factor", t,
            tex->source, d->image_count);
        return NULL;
    }
    mt->image = tw_gltf_load_image(im, (uint32_t)tex->source);
    if (!mt->image)
        return NULL;
    mt->wrap_s = mt->wrap_t = WRAP_REPEAT;
    if (tex->sampler >= 0 && (uint32_t)tex->sampler < d->sampler_count) {
        mt->wrap_s = d->samplers[tex->sampler].wrap_s;
        mt->wrap_t = d->samplers[tex->sampler].wrap_t;
    }
    mt->texcoord = (uint32_t)mat->base_color_texcoord;
    if (mat->has_uv_transform) {
        const double r = mat->uv_rotation, sx = mat->uv_scale[0], sy = mat->uv_scale[1];
        const double xf[6] = {mat->uv_offset[0], mat->uv_offset[1], cos(r) * sx, sin(r) * sy,
                             -sin(r) * sx, cos(r) * sy};
        if (!tw_gltf_all_finite(xf, 6)) {
            tw_gltf_warn_texture(im,
                                 "materials[%u].pbrMetallicRoughness.baseColorTexture.extensions."
                                 "KHR_texture_transform: a value is not finite; ignored",
                                 index);
        } else {
            mt->transformed = true;
            mt->offset[0] = xf[0];
            mt->offset[1] = xf[1];
            mt->a = xf[2];
            mt->b = xf[3];
            mt->c = xf[4];
            mt->d = xf[5];
            if (mat->uv_texcoord >= 0 && mat->uv_texcoord <= 99)
                mt->texcoord = (uint32_t)mat->uv_texcoord;
        }
    }
    mt->state = 1;
    return mt;
}

/* The accessor of attribute name if it is usable as texture coordinates
 * (want 2) or colours (want 3: VEC3 or VEC4) of nv vertices, else -1
 * (warned if present). */
static int32_t colour_attribute(struct tw_gltf_importer *im, uint32_t m, uint32_t k,
                                const char *name, uint32_t want, uint32_t nv)
{
    const struct tw_gltf_doc_primitive *p = &im->doc->meshes[m].primitives[k];
    const int32_t acc = tw_gltf_find_attribute(p, name);
    if (acc < 0)
        return -1;
    const struct tw_gltf_doc_accessor *a = &im->doc->accessors[acc];
    const bool type_ok = want == 2 ? a->type == TW_GLTF_TYPE_VEC2
                                   : (a->type == TW_GLTF_TYPE_VEC3 || a->type == TW_GLTF_TYPE_VEC4);
    /* Texture coordinates may be any 8- or 16-bit integers, normalized or
     * not (KHR_mesh_quantization); colours only normalized unsigned ones. */
    const bool comp_ok = a->component_type == TW_GLTF_COMP_FLOAT ||
                         (want == 2 && tw_gltf_is_integer(a->component_type)) ||
                         ((a->component_type == TW_GLTF_COMP_UNSIGNED_BYTE ||
                           a->component_type == TW_GLTF_COMP_UNSIGNED_SHORT) &&
                          a->normalized);
    if (!type_ok || !comp_ok || a->count != nv) {
        tw_gltf_warn_texture(im,
                             "meshes[%u].primitives[%u].attributes.%s: accessors[%d] is not %u "
                             "%s of FLOAT or %s; ignored",
                             m, k, name, acc, nv, want == 2 ? "VEC2" : "VEC3/VEC4",
                             want == 2 ? "8- or 16-bit integers"
                                       : "normalized UNSIGNED_BYTE/SHORT");
        return -1;
    }
    return acc;
}

static uint32_t wrap_texel(float coord, int32_t mode, uint32_t size)
{
    double c = isfinite(coord) ? coord : 0.0;
    switch (mode) {
    case WRAP_CLAMP_TO_EDGE:
        c = fmin(fmax(c, 0.0), 1.0);
        break;
    case WRAP_MIRRORED_REPEAT:
        c -= 2.0 * floor(c / 2.0);
        if (c > 1.0)
            c = 2.0 - c;
        break;
    default:
        c -= floor(c);
        break;
    }
    const double t = floor(c * size);
    return t <= 0.0 ? 0 : t >= size - 1 ? size - 1 : (uint32_t)t;
}

void tw_gltf_palette_finish(struct tw_gltf_palette *pal)
{
    free(pal->keys);
    free(pal->materials);
}

static uint32_t palette_hash(uint32_t key)
{
    key ^= key >> 16;
    key *= 0x7feb352du;
    key ^= key >> 15;
    key *= 0x846ca68bu;
    return key ^ key >> 16;
}

/* The material of colour rgba (0..1), added to sc if new. */
static int palette_material(struct tw_gltf_palette *pal, struct tw_gltf_scene *sc,
                            const float rgba[4], uint32_t *out)
{
    uint8_t q[4];
    for (int c = 0; c < 4; c++)
        q[c] = (uint8_t)lrintf(fminf(fmaxf(rgba[c], 0.0f), 1.0f) * 255.0f);
    const uint32_t key = (uint32_t)q[0] << 24 | (uint32_t)q[1] << 16 | (uint32_t)q[2] << 8 | q[3];
    if (2 * (pal->count + 1) > pal->size) {
        const uint32_t size = pal->size ? 2 * pal->size : 64;
        uint32_t *keys = malloc(sizeof(*keys) * size);
        uint32_t *materials = malloc(sizeof(*materials) * size);
        if (!keys || !materials) {
            free(keys);
            free(materials);
            return TW_ERR_NOMEM;
        }
        for (uint32_t s = 0; s < size; s++)
            materials[s] = UINT32_MAX;
        for (uint32_t s = 0; s < pal->size; s++) {
            if (pal->materials[s] == UINT32_MAX)
                continue;
            uint32_t h = palette_hash(pal->keys[s]) & (size - 1);
            while (materials[h] != UINT32_MAX)
                h = (h + 1) & (size - 1);
            keys[h] = pal->keys[s];
            materials[h] = pal->materials[s];
        }
        tw_gltf_palette_finish(pal);
        pal->keys = keys;
        pal->materials = materials;
        pal->size = size;
    }
    uint32_t h = palette_hash(key) & (pal->size - 1);
    while (pal->materials[h] != UINT32_MAX) {
        if (pal->keys[h] == key) {
            *out = pal->materials[h];
            return TW_OK;
        }
        h = (h + 1) & (pal->size - 1);
    }
    if (sc->material_count == pal->material_capacity) {
        if (pal->material_capacity > UINT32_MAX / 2)
            return TW_ERR_LIMIT;
        const uint32_t capacity = 2 * pal->material_capacity;
        struct tw_material *grown = realloc(sc->materials, sizeof(*grown) * capacity);
        if (!grown)
            return TW_ERR_NOMEM;
        sc->materials = grown;
        pal->material_capacity = capacity;
    }
    struct tw_material *mat = &sc->materials[sc->material_count];
    memset(mat, 0, sizeof(*mat));
    for (int c = 0; c < 4; c++)
        mat->base_color[c] = (float)q[c] / 255.0f;
    pal->keys[h] = key;
    pal->materials[h] = sc->material_count;
    pal->count++;
    *out = sc->material_count++;
    return TW_OK;
}

/* Appends prim (taking its arrays) to sc as the next primitive of gm. On
 * failure prim's arrays are freed. */
static int append_primitive(struct tw_gltf_palette *pal, struct tw_gltf_scene *sc,
                            struct tw_gltf_mesh *gm, struct tw_gltf_primitive *prim)
{
    if (sc->primitive_count == pal->primitive_capacity) {
        const uint32_t capacity = pal->primitive_capacity > UINT32_MAX / 2
                                      ? UINT32_MAX
                                      : 2 * pal->primitive_capacity + 1;
        struct tw_gltf_primitive *grown =
            capacity > sc->primitive_count
                ? realloc(sc->primitives, sizeof(*grown) * (size_t)capacity)
                : NULL;
        if (!grown) {
            free(prim->positions);
            free(prim->normals);
            free(prim->indices);
            memset(prim, 0, sizeof(*prim));
            return TW_ERR_NOMEM;
        }
        sc->primitives = grown;
        pal->primitive_capacity = capacity;
    }
    sc->primitives[sc->primitive_count++] = *prim;
    sc->vertex_count += prim->vertex_count;
    gm->primitive_count++;
    memset(prim, 0, sizeof(*prim));
    return TW_OK;
}

/* The triangles of whole listed in order[0, count) as a primitive of their
 * own, with only the vertices they use (remap: nv entries of UINT32_MAX,
 * left so). */
static int extract_triangles(const struct tw_gltf_primitive *whole, const uint32_t *order,
                             uint32_t count, uint32_t *remap, struct tw_gltf_primitive *out)
{
    memset(out, 0, sizeof(*out));
    out->indices = malloc(sizeof(uint32_t) * 3 * (size_t)count);
    if (!out->indices)
        return TW_ERR_NOMEM;
    uint32_t nv = 0;
    for (uint32_t t = 0; t < count; t++) {
        for (int c = 0; c < 3; c++) {
            const uint32_t v = whole->indices[3 * (size_t)order[t] + c];
            if (remap[v] == UINT32_MAX)
                remap[v] = nv++;
            out->indices[3 * (size_t)t + c] = remap[v];
        }
    }
    out->positions = malloc(sizeof(float) * 3 * (size_t)nv);
    out->normals = whole->normals ? malloc(sizeof(float) * 3 * (size_t)nv) : NULL;
    const bool ok = out->positions && (out->normals || !whole->normals);
    out->box = tw_box_empty();
    for (uint32_t t = 0; t < count; t++) {
        for (int c = 0; c < 3; c++) {
            const uint32_t v = whole->indices[3 * (size_t)order[t] + c];
            if (remap[v] == UINT32_MAX)
                continue;
            if (ok) {
                const uint32_t w = remap[v];
                memcpy(out->positions + 3 * (size_t)w, whole->positions + 3 * (size_t)v,
                       3 * sizeof(float));
                if (whole->normals)
                    memcpy(out->normals + 3 * (size_t)w, whole->normals + 3 * (size_t)v,
                           3 * sizeof(float));
                tw_box_add_point(&out->box, whole->positions + 3 * (size_t)v);
            }
            remap[v] = UINT32_MAX;
        }
    }
    out->vertex_count = nv;
    out->triangle_count = count;
    out->material = whole->material;
    if (!ok) {
        free(out->positions);
        free(out->normals);
        free(out->indices);
        memset(out, 0, sizeof(*out));
        return TW_ERR_NOMEM;
    }
    return TW_OK;
}

static float triangle_area(const float *positions, const uint32_t *ix)
{
    const float *a = positions + 3 * (size_t)ix[0], *b = positions + 3 * (size_t)ix[1],
                *c = positions + 3 * (size_t)ix[2];
    const float u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    const float v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const float x = u[1] * v[2] - u[2] * v[1], y = u[2] * v[0] - u[0] * v[2],
                z = u[0] * v[1] - u[1] * v[0];
    const float area = 0.5f * sqrtf(x * x + y * y + z * z);
    return isfinite(area) ? area : 0.0f;
}

/* Appends the converted primitive k of mesh m to sc, split by colour when
 * its material has a usable baseColorTexture or it has COLOR_0. Takes
 * prim's arrays in every case. */
int tw_gltf_add_primitive(struct tw_gltf_importer *im, uint32_t m, uint32_t k,
                          struct tw_gltf_palette *pal, struct tw_gltf_scene *sc,
                          struct tw_gltf_mesh *gm, struct tw_gltf_primitive *prim)
{
    const struct tw_gltf_doc *d = im->doc;
    const uint32_t material = prim->material; /* the file's, or grey */
    const struct tw_gltf_material_texture *tex =
        material < d->material_count ? material_texture(im, material) : NULL;
    const uint32_t nv = prim->vertex_count, tris = prim->triangle_count;
    int32_t uv_acc = -1;
    if (tex) {
        char name[32];
        snprintf(name, sizeof(name), "TEXCOORD_%u", tex->texcoord);
        uv_acc = colour_attribute(im, m, k, name, 2, nv);
        if (uv_acc < 0 && tw_gltf_find_attribute(&d->meshes[m].primitives[k], name) < 0)
            tw_gltf_warn_texture(im,
                                 "meshes[%u].primitives[%u]: materials[%u] has a "
                                 "baseColorTexture but the primitive has no %s; using the base "
                                 "colour factor",
                                 m, k, material, name);
    }
    const int32_t colour_acc = colour_attribute(im, m, k, "COLOR_0", 3, nv);
    if (uv_acc < 0 && colour_acc < 0)
        return append_primitive(pal, sc, gm, prim);

    int err = TW_OK;
    float *uv = NULL, *vcol = NULL, *tri_colour = NULL;
    uint32_t *order = NULL, *remap = NULL;
    uint8_t *slot = NULL;
    uint32_t colour_count = 0, first[MAX_SPLIT_COLOURS + 2], materials[MAX_SPLIT_COLOURS + 1];
    uint32_t keys[MAX_SPLIT_COLOURS + 1];
    if (uv_acc >= 0 && !(uv = malloc(sizeof(float) * 2 * (size_t)nv)))
        goto nomem;
    if (colour_acc >= 0 && !(vcol = malloc(sizeof(float) * 4 * (size_t)nv)))
        goto nomem;
    tri_colour = malloc(sizeof(float) * 3 * (size_t)tris);
    slot = malloc(tris);
    if (!tri_colour || !slot)
        goto nomem;
    if (uv && (err = tw_gltf_read_floats(im, (uint32_t)uv_acc, 2, uv)))
        goto out;
    if (vcol) {
        const bool rgba = d->accessors[colour_acc].type == TW_GLTF_TYPE_VEC4;
        if ((err = tw_gltf_read_floats(im, (uint32_t)colour_acc, rgba ? 4 : 3, vcol)))
            goto out;
        if (!rgba) /* spread VEC3 to four floats, back to front */
            for (uint32_t v = nv; v-- > 0;) {
                for (int c = 2; c >= 0; c--)
                    vcol[4 * (size_t)v + c] = vcol[3 * (size_t)v + c];
                vcol[4 * (size_t)v + 3] = 1.0f;
            }
    }

    /* A copy: palette_material() may move sc->materials. */
    float factor[4];
    memcpy(factor, sc->materials[material].base_color, sizeof(factor));
    for (uint32_t t = 0; t < tris; t++) {
        const uint32_t *ix = prim->indices + 3 * (size_t)t;
        float c[3] = {factor[0], factor[1], factor[2]};
        if (uv) {
            float u = 0.0f, v = 0.0f;
            for (int e = 0; e < 3; e++) {
                u += uv[2 * (size_t)ix[e]] / 3.0f;
                v += uv[2 * (size_t)ix[e] + 1] / 3.0f;
            }
            if (tex->transformed) {
                const double tu = tex->offset[0] + tex->a * u + tex->b * v;
                const double tv = tex->offset[1] + tex->c * u + tex->d * v;
                u = isfinite(tu) ? (float)fmax(fmin(tu, 1e9), -1e9) : 0.0f;
                v = isfinite(tv) ? (float)fmax(fmin(tv, 1e9), -1e9) : 0.0f;
            }
            const struct tw_gltf_decoded_image *img = tex->image;
            const uint32_t x = wrap_texel(u, tex->wrap_s, img->width);
            const uint32_t y = wrap_texel(v, tex->wrap_t, img->height);
            const uint8_t *texel = img->rgba + 4 * ((size_t)y * img->width + x);
            for (int e = 0; e < 3; e++)
                c[e] *= (float)texel[e] / 255.0f;
        }
        if (vcol) {
            for (int e = 0; e < 3; e++) {
                const float mean = (vcol[4 * (size_t)ix[0] + e] + vcol[4 * (size_t)ix[1] + e] +
                                    vcol[4 * (size_t)ix[2] + e]) / 3.0f;
                c[e] *= isfinite(mean) ? fminf(fmaxf(mean, 0.0f), 1.0f) : 1.0f;
            }
        }
        for (int e = 0; e < 3; e++)
            tri_colour[3 * (size_t)t + e] = fminf(fmaxf(c[e], 0.0f), 1.0f);
    }

    /* Group by 8-bit colour. Palettes with gradients (Kenney's kits) give
     * more colours than draws are worth: coarsen to 7, 6, ... 4 bits per
     * channel before giving up; a group's colour is its area-weighted mean. */
    for (int bits = 8; bits >= 4; bits--) {
        colour_count = 0;
        for (uint32_t t = 0; t < tris && colour_count <= MAX_SPLIT_COLOURS; t++) {
            uint32_t key = 0;
            for (int e = 0; e < 3; e++)
                key = key << 8 |
                      (uint32_t)lrintf(tri_colour[3 * (size_t)t + e] * 255.0f) >> (8 - bits);
            uint32_t s = 0;
            while (s < colour_count && keys[s] != key)
                s++;
            if (s == colour_count)
                keys[colour_count++] = key;
            slot[t] = (uint8_t)s;
        }
        if (colour_count <= MAX_SPLIT_COLOURS)
            break;
    }
    if (colour_count > MAX_SPLIT_COLOURS) {
        /* Too many colours for one draw each: one mean colour. */
        colour_count = 1;
        memset(slot, 0, tris);
    }
    {
        double sum[MAX_SPLIT_COLOURS + 1][4];
        memset(sum, 0, sizeof(sum));
        for (uint32_t t = 0; t < tris; t++) {
            double area = triangle_area(prim->positions, prim->indices + 3 * (size_t)t);
            if (!(area > 0.0))
                area = 1e-30;
            for (int e = 0; e < 3; e++)
                sum[slot[t]][e] += area * tri_colour[3 * (size_t)t + e];
            sum[slot[t]][3] += area;
        }
        for (uint32_t s = 0; s < colour_count; s++) {
            const float rgba[4] = {(float)(sum[s][0] / sum[s][3]), (float)(sum[s][1] / sum[s][3]),
                                   (float)(sum[s][2] / sum[s][3]), factor[3]};
            if ((err = palette_material(pal, sc, rgba, &materials[s])))
                goto out;
        }
    }
    if (colour_count == 1) {
        prim->material = materials[0];
        err = append_primitive(pal, sc, gm, prim);
        goto out;
    }
    /* Triangles grouped by colour, in their order within each group. */
    order = malloc(sizeof(uint32_t) * (size_t)tris);
    remap = malloc(sizeof(uint32_t) * (size_t)nv);
    if (!order || !remap)
        goto nomem;
    for (uint32_t v = 0; v < nv; v++)
        remap[v] = UINT32_MAX;
    memset(first, 0, sizeof(first));
    for (uint32_t t = 0; t < tris; t++)
        first[slot[t] + 1]++;
    for (uint32_t s = 1; s <= colour_count; s++)
        first[s] += first[s - 1];
    {
        uint32_t next[MAX_SPLIT_COLOURS + 2];
        memcpy(next, first, sizeof(next));
        for (uint32_t t = 0; t < tris; t++)
            order[next[slot[t]]++] = t;
    }
    for (uint32_t s = 0; s < colour_count; s++) {
        const uint32_t end = first[s + 1];
        struct tw_gltf_primitive part;
        if ((err = extract_triangles(prim, order + first[s], end - first[s], remap, &part)))
            goto out;
        part.material = materials[s];
        if ((err = append_primitive(pal, sc, gm, &part)))
            goto out;
    }
    goto out;
nomem:
    err = TW_ERR_NOMEM;
out:
    if (err == TW_ERR_NOMEM)
        tw_gltf_fail(im, err, "meshes[%u].primitives[%u]: out of memory splitting by colour", m, k);
    else if (err == TW_ERR_LIMIT)
        tw_gltf_fail(im, err, "materials: more than 2^31 colours");
    /* prim's arrays, unless append_primitive() took them. */
    free(prim->positions);
    free(prim->normals);
    free(prim->indices);
    memset(prim, 0, sizeof(*prim));
    free(uv);
    free(vcol);
    free(tri_colour);
    free(order);
    free(remap);
    free(slot);
    return err;
}
