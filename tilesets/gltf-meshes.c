/* glTF import, mesh primitives (gltf-private.h): their references and
 * types checked, their data checked without allocating (finite positions,
 * indices in range), and their conversion into triangle lists. */
#include "tiles/tiles-internal.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tilesets/gltf-private.h"

enum {
    MODE_POINTS = 0,
    MODE_LINES = 1,
    MODE_LINE_LOOP = 2,
    MODE_LINE_STRIP = 3,
    MODE_TRIANGLES = 4,
    MODE_TRIANGLE_STRIP = 5,
    MODE_TRIANGLE_FAN = 6,
};

int32_t tw_gltf_find_attribute(const struct tw_gltf_doc_primitive *p, const char *name)
{
    for (uint32_t k = 0; k < p->attribute_count; k++)
        if (p->attributes[k].name && strcmp(p->attributes[k].name, name) == 0)
            return p->attributes[k].accessor;
    return -1;
}

static const char *mode_name(int32_t mode)
{
    switch (mode) {
    case MODE_POINTS: return "POINTS";
    case MODE_LINES: return "LINES";
    case MODE_LINE_LOOP: return "LINE_LOOP";
    case MODE_LINE_STRIP: return "LINE_STRIP";
    default: return "an unknown mode";
    }
}

bool tw_gltf_draws_triangles(const struct tw_gltf_doc_primitive *p)
{
    return p->mode == MODE_TRIANGLES || p->mode == MODE_TRIANGLE_STRIP ||
           p->mode == MODE_TRIANGLE_FAN;
}

bool tw_gltf_is_integer(int32_t comp)
{
    return comp == TW_GLTF_COMP_BYTE || comp == TW_GLTF_COMP_UNSIGNED_BYTE ||
           comp == TW_GLTF_COMP_SHORT || comp == TW_GLTF_COMP_UNSIGNED_SHORT;
}

/* Vertex attribute types: glTF 2.0 §3.7.2.1 and KHR_mesh_quantization
 * (positions of any 8- or 16-bit integers, normalized or not; normals of
 * normalized BYTE or SHORT). */
static bool position_type_ok(const struct tw_gltf_doc_accessor *a)
{
    return a->type == TW_GLTF_TYPE_VEC3 &&
           ((a->component_type == TW_GLTF_COMP_FLOAT && !a->normalized) ||
            tw_gltf_is_integer(a->component_type));
}

static bool normal_type_ok(const struct tw_gltf_doc_accessor *a)
{
    return a->type == TW_GLTF_TYPE_VEC3 &&
           ((a->component_type == TW_GLTF_COMP_FLOAT && !a->normalized) ||
            ((a->component_type == TW_GLTF_COMP_BYTE || a->component_type == TW_GLTF_COMP_SHORT) &&
             a->normalized));
}

int tw_gltf_check_meshes(struct tw_gltf_importer *im)
{
    const struct tw_gltf_doc *d = im->doc;
    for (uint32_t m = 0; m < d->mesh_count; m++) {
        const struct tw_gltf_doc_mesh *mesh = &d->meshes[m];
        if (mesh->primitive_count == 0)
            return tw_gltf_fail(im, TW_ERR_FORMAT, "meshes[%u]: has no primitives", m);
        for (uint32_t k = 0; k < mesh->primitive_count; k++) {
            const struct tw_gltf_doc_primitive *p = &mesh->primitives[k];
            if (p->mode < MODE_POINTS || p->mode > MODE_TRIANGLE_FAN)
                return tw_gltf_fail(
                    im, TW_ERR_FORMAT,
                    "meshes[%u].primitives[%u].mode: %d is not a glTF primitive mode "
                    "(0 to 6)",
                    m, k, p->mode);
            for (uint32_t t = 0; t < p->attribute_count; t++) {
                const int32_t acc = p->attributes[t].accessor;
                if (acc < 0 || (uint32_t)acc >= d->accessor_count) {
                    char shown[64];
                    return tw_gltf_fail(
                        im, TW_ERR_FORMAT,
                        "meshes[%u].primitives[%u].attributes.%s: %d is not an "
                        "accessor (%u)",
                        m, k,
                        tw_log_escape(p->attributes[t].name ? p->attributes[t].name : "?", shown,
                                      sizeof(shown)),
                        acc, d->accessor_count);
                }
            }
            if (p->indices < -1 || (p->indices >= 0 && (uint32_t)p->indices >= d->accessor_count))
                return tw_gltf_fail(im, TW_ERR_FORMAT,
                                    "meshes[%u].primitives[%u].indices: %d is not an accessor (%u)",
                                    m, k, p->indices, d->accessor_count);
            if (p->material < -1 ||
                (p->material >= 0 && (uint32_t)p->material >= d->material_count))
                return tw_gltf_fail(im, TW_ERR_FORMAT,
                                    "meshes[%u].primitives[%u].material: %d is not a material (%u)",
                                    m, k, p->material, d->material_count);
            if (!tw_gltf_draws_triangles(p)) {
                /* Points and lines are valid glTF that a triangle renderer
                 * does not draw: skipped (one warning per file), never read. */
                if (im->skipped_primitives++ == 0)
                    snprintf(im->skipped_first, sizeof(im->skipped_first),
                             "meshes[%u].primitives[%u].mode: %d (%s)", m, k, p->mode,
                             mode_name(p->mode));
                continue;
            }
            const int32_t pos = tw_gltf_find_attribute(p, "POSITION");
            if (pos < 0)
                continue; /* drawn as nothing (glTF 2.0 §3.7.2.1) */
            const struct tw_gltf_doc_accessor *a = &d->accessors[pos];
            if (!position_type_ok(a))
                return tw_gltf_fail(
                    im, TW_ERR_FORMAT,
                    "meshes[%u].primitives[%u].attributes.POSITION: accessors[%d] is "
                    "%s of %s%s; positions must be VEC3 of FLOAT, or of BYTE, "
                    "UNSIGNED_BYTE, SHORT or UNSIGNED_SHORT (KHR_mesh_quantization)",
                    m, k, pos, tw_gltf_type_name(a->type), a->normalized ? "normalized " : "",
                    tw_gltf_component_name(a->component_type));
            const int32_t nrm = tw_gltf_find_attribute(p, "NORMAL");
            if (nrm >= 0) {
                const struct tw_gltf_doc_accessor *n = &d->accessors[nrm];
                if (!normal_type_ok(n) || n->count != a->count)
                    return tw_gltf_fail(
                        im, TW_ERR_FORMAT,
                        "meshes[%u].primitives[%u].attributes.NORMAL: accessors[%d] "
                        "must be %llu VEC3 like POSITION, of FLOAT or of normalized "
                        "BYTE or SHORT (KHR_mesh_quantization)",
                        m, k, nrm, (unsigned long long)a->count);
            }
            if (p->indices >= 0) {
                const struct tw_gltf_doc_accessor *ix = &d->accessors[p->indices];
                const int32_t c = ix->component_type;
                if (ix->type != TW_GLTF_TYPE_SCALAR ||
                    (c != TW_GLTF_COMP_UNSIGNED_BYTE && c != TW_GLTF_COMP_UNSIGNED_SHORT &&
                     c != TW_GLTF_COMP_UNSIGNED_INT))
                    return tw_gltf_fail(
                        im, TW_ERR_FORMAT,
                        "meshes[%u].primitives[%u].indices: accessors[%d] is %s of "
                        "%s; indices must be SCALAR of UNSIGNED_BYTE, UNSIGNED_SHORT "
                        "or UNSIGNED_INT",
                        m, k, p->indices, tw_gltf_type_name(ix->type), tw_gltf_component_name(c));
            }
        }
    }
    return TW_OK;
}

/* Triangles of a checked primitive, from its counts alone. */
int tw_gltf_primitive_triangles(struct tw_gltf_importer *im, uint32_t m, uint32_t k, uint64_t *tris)
{
    const struct tw_gltf_doc *d = im->doc;
    const struct tw_gltf_doc_primitive *p = &d->meshes[m].primitives[k];
    *tris = 0;
    const int32_t pos = tw_gltf_find_attribute(p, "POSITION");
    if (pos < 0 || !tw_gltf_draws_triangles(p))
        return TW_OK;
    const uint64_t n = p->indices >= 0 ? d->accessors[p->indices].count : d->accessors[pos].count;
    if (p->mode == MODE_TRIANGLES) {
        if (n % 3 != 0)
            return tw_gltf_fail(im, TW_ERR_FORMAT,
                                "meshes[%u].primitives[%u]: %llu %s is not a multiple of 3", m, k,
                                (unsigned long long)n, p->indices >= 0 ? "indices" : "vertices");
        *tris = n / 3;
    } else {
        *tris = n >= 3 ? n - 2 : 0;
    }
    return TW_OK;
}

/* The largest value of an index component type, which glTF reserves
 * (primitive restart) and forbids in indices. */
static uint32_t restart_value(int32_t comp)
{
    return comp == TW_GLTF_COMP_UNSIGNED_BYTE    ? 0xffu
           : comp == TW_GLTF_COMP_UNSIGNED_SHORT ? 0xffffu
                                                 : 0xffffffffu;
}

/* Reads the index accessor ia once: its largest value and whether it holds
 * the restart value, sparse substitutes included (and the base values they
 * replace). */
static int read_index_facts(struct tw_gltf_importer *im, int32_t ia)
{
    struct tw_gltf_accessor_facts *f = &im->facts[ia];
    if (f->flags & TW_GLTF_FACT_INDICES_READ)
        return TW_OK;
    const struct tw_gltf_doc *d = im->doc;
    const struct tw_gltf_doc_accessor *a = &d->accessors[ia];
    const uint64_t size = tw_gltf_component_size(a->component_type);
    uint64_t stride;
    const uint8_t *base = tw_gltf_accessor_base(d, a, &stride);
    int err = tw_gltf_charge_check(
        im, ia, (base ? a->count * size : 0) + (a->sparse ? (uint64_t)a->sparse_count * size : 0));
    if (err)
        return err;
    const uint32_t restart = restart_value(a->component_type);
    uint32_t max = 0;
    bool has_restart = false;
    for (uint64_t e = 0; base && e < a->count; e++) {
        const uint32_t i = tw_gltf_load_uint(base + e * stride, a->component_type);
        max = i > max ? i : max;
        has_restart |= i == restart;
    }
    if (a->sparse) {
        const uint8_t *val = tw_gltf_view_data(d, a->sparse_values_view, a->sparse_values_offset);
        for (int32_t e = 0; e < a->sparse_count; e++) {
            const uint32_t i = tw_gltf_load_uint(val + size * (uint64_t)e, a->component_type);
            max = i > max ? i : max;
            has_restart |= i == restart;
        }
    }
    f->index_max = max;
    f->flags |= TW_GLTF_FACT_INDICES_READ | (has_restart ? TW_GLTF_FACT_RESTART : 0);
    return TW_OK;
}

/* Checks the data of primitive k of mesh m without allocating: positions
 * finite and within +-TW_TILES_MAX_MESH_COORD, every index below the vertex
 * count and never the restart value (sparse substitutes included; base
 * values that a substitute replaces must be in range too). Runs on every
 * triangle primitive, drawn or not; each accessor is read once. */
static int check_primitive_data(struct tw_gltf_importer *im, uint32_t m, uint32_t k)
{
    const struct tw_gltf_doc *d = im->doc;
    const struct tw_gltf_doc_primitive *p = &d->meshes[m].primitives[k];
    const int32_t pos = tw_gltf_find_attribute(p, "POSITION");
    if (pos < 0 || !tw_gltf_draws_triangles(p))
        return TW_OK;
    const struct tw_gltf_doc_accessor *pa = &d->accessors[pos];
    uint64_t stride;
    const uint8_t *base = tw_gltf_accessor_base(d, pa, &stride);
    /* Integer positions (KHR_mesh_quantization) are small by their type. */
    const bool floats = pa->component_type == TW_GLTF_COMP_FLOAT;
    int err;
    if (floats && !(im->facts[pos].flags & TW_GLTF_FACT_POSITIONS_OK)) {
        if ((err = tw_gltf_charge_check(im, pos,
                                        (base ? 12 * pa->count : 0) +
                                            (pa->sparse ? 12 * (uint64_t)pa->sparse_count : 0))))
            return err;
        for (uint64_t v = 0; base && v < pa->count; v++) {
            for (int c = 0; c < 3; c++) {
                const float x = tw_gltf_load_float(base + v * stride + 4 * c);
                if (!isfinite(x))
                    return tw_gltf_fail(
                        im, TW_ERR_FORMAT,
                        "meshes[%u].primitives[%u].attributes.POSITION: accessors[%d] "
                        "element %llu is not finite",
                        m, k, pos, (unsigned long long)v);
                if (fabsf(x) > TW_TILES_MAX_MESH_COORD)
                    return tw_gltf_fail(
                        im, TW_ERR_LIMIT,
                        "meshes[%u].primitives[%u].attributes.POSITION: accessors[%d] "
                        "element %llu has %c = %g, beyond +-%g",
                        m, k, pos, (unsigned long long)v, "xyz"[c], x,
                        (double)TW_TILES_MAX_MESH_COORD);
            }
        }
        if (pa->sparse) {
            const uint8_t *val =
                tw_gltf_view_data(d, pa->sparse_values_view, pa->sparse_values_offset);
            for (int32_t e = 0; e < pa->sparse_count; e++) {
                for (int c = 0; c < 3; c++) {
                    const float x = tw_gltf_load_float(val + 12 * (uint64_t)e + 4 * c);
                    if (!isfinite(x))
                        return tw_gltf_fail(im, TW_ERR_FORMAT,
                                            "meshes[%u].primitives[%u].attributes.POSITION: "
                                            "accessors[%d] sparse value %d is not finite",
                                            m, k, pos, e);
                    if (fabsf(x) > TW_TILES_MAX_MESH_COORD)
                        return tw_gltf_fail(
                            im, TW_ERR_LIMIT,
                            "meshes[%u].primitives[%u].attributes.POSITION: "
                            "accessors[%d] sparse value %d has %c = %g, beyond +-%g",
                            m, k, pos, e, "xyz"[c], x, (double)TW_TILES_MAX_MESH_COORD);
                }
            }
        }
        im->facts[pos].flags |= TW_GLTF_FACT_POSITIONS_OK;
    }
    if (p->indices < 0)
        return TW_OK;
    if ((err = read_index_facts(im, p->indices)))
        return err;
    const struct tw_gltf_accessor_facts *f = &im->facts[p->indices];
    const uint64_t nv = pa->count;
    if (f->index_max < nv && !(f->flags & TW_GLTF_FACT_RESTART))
        return TW_OK;
    /* A bad index: find the first, for the message (once: it ends the
     * import). */
    const struct tw_gltf_doc_accessor *ia = &d->accessors[p->indices];
    const uint32_t restart = restart_value(ia->component_type);
    base = tw_gltf_accessor_base(d, ia, &stride);
    for (uint64_t e = 0; base && e < ia->count; e++) {
        const uint32_t i = tw_gltf_load_uint(base + e * stride, ia->component_type);
        if (i >= nv)
            return tw_gltf_fail(
                im, TW_ERR_FORMAT,
                "meshes[%u].primitives[%u].indices: accessors[%d] element %llu is %u, "
                "not below the vertex count %llu",
                m, k, p->indices, (unsigned long long)e, i, (unsigned long long)nv);
        if (i == restart)
            return tw_gltf_fail(
                im, TW_ERR_FORMAT,
                "meshes[%u].primitives[%u].indices: accessors[%d] element %llu is %u, "
                "the largest %s, which glTF reserves (primitive restart)",
                m, k, p->indices, (unsigned long long)e, i,
                tw_gltf_component_name(ia->component_type));
    }
    const uint64_t size = tw_gltf_component_size(ia->component_type);
    for (int32_t e = 0; ia->sparse && e < ia->sparse_count; e++) {
        const uint8_t *val = tw_gltf_view_data(d, ia->sparse_values_view, ia->sparse_values_offset);
        const uint32_t i = tw_gltf_load_uint(val + size * (uint64_t)e, ia->component_type);
        if (i >= nv)
            return tw_gltf_fail(
                im, TW_ERR_FORMAT,
                "meshes[%u].primitives[%u].indices: accessors[%d] sparse value %d is "
                "%u, not below the vertex count %llu",
                m, k, p->indices, e, i, (unsigned long long)nv);
        if (i == restart)
            return tw_gltf_fail(
                im, TW_ERR_FORMAT,
                "meshes[%u].primitives[%u].indices: accessors[%d] sparse value %d is "
                "%u, the largest %s, which glTF reserves (primitive restart)",
                m, k, p->indices, e, i, tw_gltf_component_name(ia->component_type));
    }
    /* Not reached: read_index_facts() saw one of the values above. */
    return tw_gltf_fail(
        im, TW_ERR_FORMAT,
        "meshes[%u].primitives[%u].indices: accessors[%d] holds an index not below the "
        "vertex count %llu, or the restart value",
        m, k, p->indices, (unsigned long long)nv);
}

int tw_gltf_check_mesh_data(struct tw_gltf_importer *im)
{
    int err = TW_OK;
    for (uint32_t m = 0; m < im->doc->mesh_count && !err; m++)
        for (uint32_t k = 0; k < im->doc->meshes[m].primitive_count && !err; k++)
            err = check_primitive_data(im, m, k);
    return err;
}

/* Converts primitive k of mesh m into out (zeroed). A primitive that draws
 * nothing leaves out->triangle_count at 0. */
int tw_gltf_convert_primitive(struct tw_gltf_importer *im, uint32_t m, uint32_t k, uint32_t grey,
                              struct tw_gltf_primitive *out)
{
    const struct tw_gltf_doc *d = im->doc;
    const struct tw_gltf_doc_primitive *p = &d->meshes[m].primitives[k];
    uint32_t *list = NULL;
    int err;
    uint64_t tris;
    if ((err = tw_gltf_primitive_triangles(im, m, k, &tris)) || tris == 0)
        return err;
    const int32_t pos = tw_gltf_find_attribute(p, "POSITION");
    const struct tw_gltf_doc_accessor *pa = &d->accessors[pos];
    const uint32_t nv = (uint32_t)pa->count;
    out->vertex_count = nv;
    out->material = p->material >= 0 ? (uint32_t)p->material : grey;
    out->positions = malloc(sizeof(float) * 3 * (size_t)nv);
    out->indices = malloc(sizeof(uint32_t) * 3 * (size_t)tris);
    if (!out->positions || !out->indices)
        return tw_gltf_fail(im, TW_ERR_NOMEM, "meshes[%u].primitives[%u]: out of memory", m, k);
    if ((err = tw_gltf_read_floats(im, (uint32_t)pos, 3, out->positions)))
        return err;
    out->box = tw_box_empty();
    for (uint32_t v = 0; v < nv; v++) {
        const float *x = out->positions + 3 * (size_t)v;
        if (!isfinite(x[0]) || !isfinite(x[1]) || !isfinite(x[2]))
            return tw_gltf_fail(
                im, TW_ERR_FORMAT,
                "meshes[%u].primitives[%u].attributes.POSITION: accessors[%d] element "
                "%u is not finite",
                m, k, pos, v);
        tw_box_add_point(&out->box, x);
    }

    const int32_t nrm = tw_gltf_find_attribute(p, "NORMAL");
    if (nrm >= 0) {
        out->normals = malloc(sizeof(float) * 3 * (size_t)nv);
        if (!out->normals)
            return tw_gltf_fail(im, TW_ERR_NOMEM, "meshes[%u].primitives[%u]: out of memory", m, k);
        if ((err = tw_gltf_read_floats(im, (uint32_t)nrm, 3, out->normals)))
            return err;
        if (d->accessors[nrm].component_type != TW_GLTF_COMP_FLOAT) {
            /* Quantised normals are unit length only to within a step. */
            for (uint32_t v = 0; v < nv; v++) {
                float *x = out->normals + 3 * (size_t)v;
                const float len = sqrtf(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
                if (len > 0.0f)
                    for (int c = 0; c < 3; c++)
                        x[c] /= len;
            }
        }
        for (uint64_t c = 0; c < 3ull * nv; c++) {
            if (!isfinite(out->normals[c])) {
                /* Normals are optional: drop them rather than the mesh. */
                free(out->normals);
                out->normals = NULL;
                break;
            }
        }
    }

    /* The primitive's vertex order: its index list, or 0 .. n-1. */
    uint64_t n = nv;
    if (p->indices >= 0) {
        n = d->accessors[p->indices].count;
        list = malloc(sizeof(uint32_t) * (size_t)n);
        if (!list)
            return tw_gltf_fail(im, TW_ERR_NOMEM, "meshes[%u].primitives[%u]: out of memory", m, k);
        if ((err = tw_gltf_read_uints(im, (uint32_t)p->indices, list)))
            goto out;
        for (uint64_t e = 0; e < n; e++) {
            if (list[e] >= nv) {
                err =
                    tw_gltf_fail(im, TW_ERR_FORMAT,
                                 "meshes[%u].primitives[%u].indices: accessors[%d] element %llu is "
                                 "%u, not below the vertex count %u",
                                 m, k, p->indices, (unsigned long long)e, list[e], nv);
                goto out;
            }
        }
    }
#define VERTEX(e) (list ? list[(e)] : (uint32_t)(e))
    uint32_t *ix = out->indices;
    for (uint64_t t = 0; t < tris; t++) {
        switch (p->mode) {
        case MODE_TRIANGLES:
            ix[0] = VERTEX(3 * t);
            ix[1] = VERTEX(3 * t + 1);
            ix[2] = VERTEX(3 * t + 2);
            break;
        case MODE_TRIANGLE_STRIP: /* odd triangles swap to keep the winding */
            ix[0] = VERTEX(t + (t & 1));
            ix[1] = VERTEX(t + 1 - (t & 1));
            ix[2] = VERTEX(t + 2);
            break;
        default: /* MODE_TRIANGLE_FAN */
            ix[0] = VERTEX(t + 1);
            ix[1] = VERTEX(t + 2);
            ix[2] = VERTEX(0);
            break;
        }
        ix += 3;
    }
#undef VERTEX
    out->triangle_count = (uint32_t)tris;
out:
    free(list);
    return err;
}
