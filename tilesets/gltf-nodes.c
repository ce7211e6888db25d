/* glTF import, the node hierarchy (gltf-private.h): checked to be a forest
 * (no cycle, one parent per node) and walked iteratively, so that a deep
 * hierarchy cannot exhaust the stack, into the scene's instances, meshes and
 * materials. */
#include "tiles/tiles-internal.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "tilesets/gltf-private.h"

static const float default_grey[4] = {0.6f, 0.6f, 0.6f, 1.0f};

bool tw_gltf_all_finite(const double *v, uint32_t n)
{
    for (uint32_t k = 0; k < n; k++)
        if (!isfinite(v[k]))
            return false;
    return true;
}

int tw_gltf_check_nodes(struct tw_gltf_importer *im, int32_t *parent)
{
    const struct tw_gltf_doc *d = im->doc;
    for (uint32_t k = 0; k < d->node_count; k++)
        parent[k] = -1;
    for (uint32_t k = 0; k < d->node_count; k++) {
        const struct tw_gltf_doc_node *n = &d->nodes[k];
        if (n->mesh < -1 || (n->mesh >= 0 && (uint32_t)n->mesh >= d->mesh_count))
            return tw_gltf_fail(im, TW_ERR_FORMAT, "nodes[%u].mesh: %d is not a mesh (%u)", k,
                                n->mesh, d->mesh_count);
        for (uint32_t c = 0; c < n->child_count; c++) {
            const int child = n->children[c];
            if (child < 0 || (uint32_t)child >= d->node_count)
                return tw_gltf_fail(im, TW_ERR_FORMAT,
                                    "nodes[%u].children[%u]: %d is not a node (%u)", k, c, child,
                                    d->node_count);
            if ((uint32_t)child == k)
                return tw_gltf_fail(im, TW_ERR_FORMAT,
                                    "nodes[%u].children[%u]: the node is its own child (a cycle)",
                                    k, c);
            if (parent[child] >= 0)
                return tw_gltf_fail(
                    im, TW_ERR_FORMAT,
                    "nodes[%u].children[%u]: nodes[%d] is already a child of nodes[%d]; "
                    "a node has at most one parent",
                    k, c, child, parent[child]);
            parent[child] = (int32_t)k;
        }
        const struct {
            const char *what;
            uint32_t given, want;
            const double *values;
        } props[4] = {
            {"matrix", n->matrix_count, 16, n->matrix},
            {"translation", n->translation_count, 3, n->translation},
            {"rotation", n->rotation_count, 4, n->rotation},
            {"scale", n->scale_count, 3, n->scale},
        };
        for (int p = 0; p < 4; p++) {
            if (props[p].given && props[p].given != props[p].want)
                return tw_gltf_fail(im, TW_ERR_FORMAT, "nodes[%u].%s: has %u values, not %u", k,
                                    props[p].what, props[p].given, props[p].want);
            if (props[p].given && !tw_gltf_all_finite(props[p].values, props[p].want))
                return tw_gltf_fail(im, TW_ERR_FORMAT, "nodes[%u].%s: a value is not finite", k,
                                    props[p].what);
            /* Finite but huge values would overflow what is made of them
             * (boxes, Embree's SAH binning): a node moves or scales by at
             * most TW_TILES_MAX_MESH_COORD, and the placed meshes must end
             * within TW_TILES_MAX_COORD (tw_gltf_build_scene()). */
            for (uint32_t e = 0; props[p].given && e < props[p].want; e++)
                if (fabs(props[p].values[e]) > TW_TILES_MAX_MESH_COORD)
                    return tw_gltf_fail(im, TW_ERR_LIMIT, "nodes[%u].%s: %g is beyond +-%g", k,
                                        props[p].what, props[p].values[e],
                                        (double)TW_TILES_MAX_MESH_COORD);
        }
        if (n->matrix_count && (n->translation_count || n->rotation_count || n->scale_count))
            return tw_gltf_fail(im, TW_ERR_FORMAT,
                                "nodes[%u]: has both a matrix and translation/rotation/scale", k);
        if (n->matrix_count && (n->matrix[3] != 0.0 || n->matrix[7] != 0.0 ||
                                n->matrix[11] != 0.0 || n->matrix[15] != 1.0))
            return tw_gltf_fail(im, TW_ERR_FORMAT,
                                "nodes[%u].matrix: is not affine (its last row is not 0 0 0 1)", k);
        if (n->rotation_count) {
            const double *q = n->rotation;
            const double len = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
            if (!(len > 1e-6) || !isfinite(len))
                return tw_gltf_fail(im, TW_ERR_FORMAT,
                                    "nodes[%u].rotation: is not a rotation (length %g)", k, len);
        }
    }
    /* With one parent per node, a cycle is a chain of parents that never
     * reaches a root: walk up from every node, marking what is known to end
     * at a root. Linear time overall. state: 0 unknown, 1 on the path, 2
     * rooted. */
    uint8_t *state = calloc(d->node_count ? d->node_count : 1, 1);
    if (!state)
        return tw_gltf_fail(im, TW_ERR_NOMEM, "nodes: out of memory");
    int err = TW_OK;
    for (uint32_t k = 0; k < d->node_count && !err; k++) {
        uint32_t n = k;
        while (state[n] == 0 && parent[n] >= 0) {
            state[n] = 1;
            n = (uint32_t)parent[n];
        }
        if (state[n] == 1) {
            /* n was reached twice on this walk: it lies on a cycle. Name the
             * edge that closes it: n's parent lists n as a child. */
            const uint32_t p = (uint32_t)parent[n];
            uint32_t c = 0;
            while (d->nodes[p].children[c] != (int)n)
                c++;
            err = tw_gltf_fail(
                im, TW_ERR_FORMAT,
                "nodes[%u].children[%u]: nodes[%u] is an ancestor of nodes[%u] (a cycle)", p, c, n,
                p);
            break;
        }
        for (uint32_t m = k; state[m] == 1; m = (uint32_t)parent[m]) {
            state[m] = 2;
            if (parent[m] < 0)
                break;
        }
        state[n] = 2;
    }
    free(state);
    return err;
}

/* Row-major affine 3x4 in double. */
static void node_local(const struct tw_gltf_doc_node *n, double out[12])
{
    if (n->matrix_count) {
        for (int r = 0; r < 3; r++)
            for (int c = 0; c < 4; c++)
                out[4 * r + c] = n->matrix[4 * c + r]; /* glTF is column-major */
        return;
    }
    double t[3] = {0, 0, 0}, q[4] = {0, 0, 0, 1}, s[3] = {1, 1, 1};
    if (n->translation_count)
        memcpy(t, n->translation, sizeof(t));
    if (n->rotation_count) {
        const double len = sqrt(n->rotation[0] * n->rotation[0] + n->rotation[1] * n->rotation[1] +
                                n->rotation[2] * n->rotation[2] + n->rotation[3] * n->rotation[3]);
        for (int k = 0; k < 4; k++)
            q[k] = n->rotation[k] / len;
    }
    if (n->scale_count)
        memcpy(s, n->scale, sizeof(s));
    const double x = q[0], y = q[1], z = q[2], w = q[3];
    const double r[9] = {
        1 - 2 * (y * y + z * z), 2 * (x * y - z * w),     2 * (x * z + y * w),
        2 * (x * y + z * w),     1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
        2 * (x * z - y * w),     2 * (y * z + x * w),     1 - 2 * (x * x + y * y),
    };
    for (int row = 0; row < 3; row++) {
        for (int c = 0; c < 3; c++)
            out[4 * row + c] = r[3 * row + c] * s[c];
        out[4 * row + 3] = t[row];
    }
}

void tw_gltf_compose(const double a[12], const double b[12], double out[12])
{
    for (int r = 0; r < 3; r++) {
        for (int c = 0; c < 4; c++) {
            double v = a[4 * r] * b[c] + a[4 * r + 1] * b[4 + c] + a[4 * r + 2] * b[8 + c];
            if (c == 3)
                v += a[4 * r + 3];
            out[4 * r + c] = v;
        }
    }
}

/* Builds the scene from a checked document. Linear in the document's size:
 * every node is visited once, every mesh's triangles counted once. */
int tw_gltf_build_scene(struct tw_gltf_importer *im, const int32_t *parent,
                        struct tw_gltf_scene *sc)
{
    const struct tw_gltf_doc *d = im->doc;
    int err = TW_OK;
    uint32_t *stack = NULL, *mesh_slot = NULL, *instance_node = NULL;
    uint64_t *mesh_tris = NULL;
    uint8_t *listed = NULL;
    double *world = NULL;
    struct tw_gltf_palette pal = {0};

    /* Which nodes the scene starts from. */
    const int *roots = NULL;
    uint32_t root_count = 0;
    int32_t scene_index = d->default_scene;
    if (scene_index < -1 || (scene_index >= 0 && (uint32_t)scene_index >= d->scene_count))
        return tw_gltf_fail(im, TW_ERR_FORMAT, "scene: %d is not a scene (%u)", scene_index,
                            d->scene_count);
    if (scene_index < 0 && d->scene_count > 0)
        scene_index = 0;
    const size_t nodes = d->node_count ? d->node_count : 1;
    const size_t meshes = d->mesh_count ? d->mesh_count : 1;
    stack = malloc(sizeof(*stack) * nodes);
    world = malloc(sizeof(*world) * 12 * nodes);
    mesh_slot = malloc(sizeof(*mesh_slot) * meshes);
    mesh_tris = malloc(sizeof(*mesh_tris) * meshes);
    instance_node = malloc(sizeof(*instance_node) * nodes);
    listed = calloc(nodes, 1);
    sc->instances = malloc(sizeof(*sc->instances) * nodes);
    if (!stack || !world || !mesh_slot || !mesh_tris || !instance_node || !listed ||
        !sc->instances) {
        err = tw_gltf_fail(im, TW_ERR_NOMEM, "nodes: out of memory");
        goto out;
    }
    uint32_t top = 0;
    if (scene_index >= 0) {
        roots = d->scenes[scene_index].nodes;
        root_count = d->scenes[scene_index].node_count;
        for (uint32_t k = 0; k < root_count; k++) {
            const int n = roots[k];
            if (n < 0 || (uint32_t)n >= d->node_count) {
                err = tw_gltf_fail(im, TW_ERR_FORMAT, "scenes[%d].nodes[%u]: %d is not a node (%u)",
                                   scene_index, k, n, d->node_count);
                goto out;
            }
            if (parent[n] >= 0) {
                err = tw_gltf_fail(
                    im, TW_ERR_FORMAT,
                    "scenes[%d].nodes[%u]: nodes[%d] is not a root (a child of nodes[%d])",
                    scene_index, k, n, parent[n]);
                goto out;
            }
            if (listed[n]) {
                err = tw_gltf_fail(im, TW_ERR_FORMAT,
                                   "scenes[%d].nodes[%u]: nodes[%d] is listed twice", scene_index,
                                   k, n);
                goto out;
            }
            listed[n] = 1;
            stack[top++] = (uint32_t)n;
        }
    } else {
        for (uint32_t n = 0; n < d->node_count; n++)
            if (parent[n] < 0)
                stack[top++] = n;
    }
    for (uint32_t k = 0; k < top; k++)
        node_local(&d->nodes[stack[k]], world + 12 * (size_t)stack[k]);
    /* Pop in document order. */
    for (uint32_t a = 0, b = top; a + 1 < b; a++, b--) {
        const uint32_t t = stack[a];
        stack[a] = stack[b - 1];
        stack[b - 1] = t;
    }
    for (uint32_t m = 0; m < d->mesh_count; m++) {
        mesh_slot[m] = UINT32_MAX;
        mesh_tris[m] = UINT64_MAX; /* not counted yet */
    }

    /* Depth first; every node is pushed at most once (one parent, no cycle). */
    uint64_t drawn = 0, vertices = 0, converted = 0;
    while (top > 0) {
        const uint32_t n = stack[--top];
        const struct tw_gltf_doc_node *node = &d->nodes[n];
        const double *w = world + 12 * (size_t)n;
        for (uint32_t c = node->child_count; c-- > 0;) {
            const uint32_t child = (uint32_t)node->children[c];
            double local[12];
            node_local(&d->nodes[child], local);
            tw_gltf_compose(w, local, world + 12 * (size_t)child);
            stack[top++] = child;
        }
        if (node->mesh < 0)
            continue;
        const uint32_t m = (uint32_t)node->mesh;
        if (mesh_tris[m] == UINT64_MAX) {
            uint64_t tris = 0;
            for (uint32_t k = 0; k < d->meshes[m].primitive_count; k++) {
                uint64_t t;
                if ((err = tw_gltf_primitive_triangles(im, m, k, &t)))
                    goto out;
                tris += t;
            }
            mesh_tris[m] = tris;
            if (tris == 0)
                continue; /* draws nothing */
            mesh_slot[m] = sc->mesh_count++;
            sc->unique_triangles += tris;
            /* Accessors without a buffer view hold any count in no bytes:
             * bound vertices too before anything is allocated for them, and
             * what converting takes by what was read. */
            for (uint32_t k = 0; k < d->meshes[m].primitive_count; k++) {
                const struct tw_gltf_doc_primitive *p = &d->meshes[m].primitives[k];
                const int32_t pos = tw_gltf_find_attribute(p, "POSITION");
                if (pos < 0 || !tw_gltf_draws_triangles(p))
                    continue;
                const uint64_t nv = d->accessors[pos].count;
                uint64_t t;
                tw_gltf_primitive_triangles(im, m, k, &t);
                vertices += nv;
                converted += 12 * nv * (tw_gltf_find_attribute(p, "NORMAL") >= 0 ? 2 : 1) + 12 * t +
                             (p->indices >= 0 ? 4 * d->accessors[p->indices].count : 0);
            }
            if (vertices > 3 * im->settings.max_triangles) {
                err = tw_gltf_fail(
                    im, TW_ERR_LIMIT,
                    "meshes[%u]: the scene's meshes have more than %llu vertices (3 per "
                    "triangle of the limit)",
                    m, (unsigned long long)(3 * im->settings.max_triangles));
                goto out;
            }
            if (sc->unique_triangles > im->settings.max_triangles) {
                err =
                    tw_gltf_fail(im, TW_ERR_LIMIT, "meshes: more than the limit of %llu triangles",
                                 (unsigned long long)im->settings.max_triangles);
                goto out;
            }
            const uint64_t allowed = TW_GLTF_MEMORY_BASE + TW_GLTF_MEMORY_PER_BYTE * im->bytes_read;
            if (converted > allowed) {
                char a[32], b[32];
                err = tw_gltf_fail(
                    im, TW_ERR_LIMIT,
                    "meshes[%u]: converting the scene's meshes would take %s, more than "
                    "the %s allowed for %llu bytes of file and buffers (64 MiB + 32 "
                    "bytes per byte)",
                    m, tw_gltf_byte_size(converted, a, sizeof(a)),
                    tw_gltf_byte_size(allowed, b, sizeof(b)), (unsigned long long)im->bytes_read);
                goto out;
            }
        }
        if (mesh_tris[m] == 0)
            continue;
        struct tw_gltf_instance *in = &sc->instances[sc->instance_count];
        for (int k = 0; k < 12; k++) {
            /* Checked in double before the conversion to float. */
            if (!isfinite(w[k])) {
                err = tw_gltf_fail(im, TW_ERR_FORMAT,
                                   "nodes[%u]: its transform, composed with its ancestors', is not "
                                   "finite",
                                   n);
                goto out;
            }
            if (fabs(w[k]) > TW_TILES_MAX_COORD) {
                err = tw_gltf_fail(
                    im, TW_ERR_LIMIT,
                    "nodes[%u]: its transform, composed with its ancestors', has %s %g, "
                    "beyond +-%g",
                    n, k % 4 == 3 ? "a translation of" : "a scale or rotation term of", w[k],
                    (double)TW_TILES_MAX_COORD);
                goto out;
            }
            in->transform[k] = (float)w[k];
        }
        in->mesh = mesh_slot[m];
        instance_node[sc->instance_count] = n;
        sc->instance_count++;
        /* Drawn triangles are counted from the document's counts, before
         * anything is converted, so that the limit holds first. */
        drawn += mesh_tris[m];
        if (drawn > im->settings.max_triangles) {
            err = tw_gltf_fail(im, TW_ERR_LIMIT,
                               "nodes[%u]: the scene draws more than the limit of %llu triangles",
                               n, (unsigned long long)im->settings.max_triangles);
            goto out;
        }
    }
    if (sc->instance_count == 0) {
        err = tw_gltf_fail(im, TW_ERR_FORMAT, "%s: draws nothing (no node with a triangle mesh)",
                           scene_index >= 0 ? "the scene" : "the document");
        goto out;
    }
    sc->triangle_count = drawn;

    /* Materials: the file's, then grey for primitives without one. */
    sc->material_count = d->material_count + 1;
    sc->materials = malloc(sizeof(*sc->materials) * sc->material_count);
    if (!sc->materials) {
        err = tw_gltf_fail(im, TW_ERR_NOMEM, "materials: out of memory");
        goto out;
    }
    for (uint32_t k = 0; k < d->material_count; k++) {
        const struct tw_gltf_doc_material *mat = &d->materials[k];
        if (mat->base_color_count != 4 || !tw_gltf_all_finite(mat->base_color, 4)) {
            err =
                tw_gltf_fail(im, TW_ERR_FORMAT,
                             "materials[%u].pbrMetallicRoughness.baseColorFactor: must be 4 finite "
                             "numbers",
                             k);
            goto out;
        }
        for (int c = 0; c < 4; c++)
            sc->materials[k].base_color[c] = (float)fmin(fmax(mat->base_color[c], 0.0), 1.0);
    }
    memcpy(sc->materials[d->material_count].base_color, default_grey, sizeof(default_grey));

    /* Meshes, in slot order; colour splits append more primitives and
     * materials (after grey). */
    uint32_t primitive_total = 0;
    for (uint32_t m = 0; m < d->mesh_count; m++)
        if (mesh_slot[m] != UINT32_MAX)
            primitive_total += d->meshes[m].primitive_count;
    pal.material_capacity = sc->material_count;
    pal.primitive_capacity = primitive_total;
    sc->meshes = calloc(sc->mesh_count, sizeof(*sc->meshes));
    sc->primitives = calloc(primitive_total, sizeof(*sc->primitives));
    if (!sc->meshes || !sc->primitives) {
        err = tw_gltf_fail(im, TW_ERR_NOMEM, "meshes: out of memory");
        goto out;
    }
    for (uint32_t m = 0; m < d->mesh_count; m++) {
        const uint32_t slot = mesh_slot[m];
        if (slot == UINT32_MAX)
            continue;
        struct tw_gltf_mesh *gm = &sc->meshes[slot];
        gm->first_primitive = sc->primitive_count;
        for (uint32_t k = 0; k < d->meshes[m].primitive_count; k++) {
            struct tw_gltf_primitive prim = {0};
            err = tw_gltf_convert_primitive(im, m, k, d->material_count, &prim);
            if (prim.triangle_count == 0 || err) {
                free(prim.positions);
                free(prim.normals);
                free(prim.indices);
                if (err)
                    goto out;
                continue;
            }
            if ((err = tw_gltf_add_primitive(im, m, k, &pal, sc, gm, &prim)))
                goto out;
        }
    }
    bool grey_used = false;
    for (uint32_t k = 0; k < sc->primitive_count; k++)
        grey_used |= sc->primitives[k].material == d->material_count;
    if (!grey_used) {
        /* Drop grey: baked colours move down one. */
        const uint32_t grey = d->material_count;
        memmove(sc->materials + grey, sc->materials + grey + 1,
                sizeof(*sc->materials) * (sc->material_count - grey - 1));
        sc->material_count--;
        for (uint32_t k = 0; k < sc->primitive_count; k++)
            if (sc->primitives[k].material > grey)
                sc->primitives[k].material--;
    }

    /* Every drawn mesh, placed, within reach of its tile (tiles.h,
     * TW_TILES_MAX_COORD): named by the node that places it. */
    sc->bounds = tw_box_empty();
    for (uint32_t k = 0; k < sc->instance_count; k++) {
        const struct tw_gltf_instance *in = &sc->instances[k];
        const struct tw_gltf_mesh *gm = &sc->meshes[in->mesh];
        struct tw_box placed = tw_box_empty();
        for (uint32_t p = 0; p < gm->primitive_count; p++) {
            struct tw_box b = tw_box_transform(&sc->primitives[gm->first_primitive + p].box,
                                               in->transform);
            tw_box_add_box(&placed, &b);
        }
        for (int a = 0; a < 3 && !tw_box_is_empty(&placed); a++) {
            const float lo = placed.min[a], hi = placed.max[a];
            if (!(lo >= -TW_TILES_MAX_COORD) || !(hi <= TW_TILES_MAX_COORD)) {
                err = tw_gltf_fail(
                    im, TW_ERR_LIMIT,
                    "nodes[%u]: its mesh, placed by the node's transform composed with "
                    "its ancestors', reaches %c = %g m, beyond +-%g m",
                    instance_node[k], "xyz"[a], !(lo >= -TW_TILES_MAX_COORD) ? lo : hi,
                    (double)TW_TILES_MAX_COORD);
                goto out;
            }
        }
        tw_box_add_box(&sc->bounds, &placed);
    }
    for (int k = 0; k < 3; k++) {
        if (!isfinite(sc->bounds.min[k]) || !isfinite(sc->bounds.max[k])) {
            err = tw_gltf_fail(im, TW_ERR_FORMAT, "the scene's bounds are not finite");
            goto out;
        }
    }
out:
    tw_gltf_palette_finish(&pal);
    free(stack);
    free(world);
    free(mesh_slot);
    free(mesh_tris);
    free(instance_node);
    free(listed);
    return err;
}
