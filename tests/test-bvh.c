/*
 * test-bvh: structure of the Embree-built and median-split BVHs on
 * hand-made prototypes, and invariants, leaf rules, tight-box lists and SAH
 * quality on synthetic and city prototypes. Prints a build table to stdout.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bvh/bvh.h"
#include "tileworld/tilesets.h"
#include "tests/check.h"
#include "tiles/tiles-internal.h"

/* ---- hand-made prototypes ------------------------------------------------ */

struct test_proto {
    struct tw_prototype proto;
    struct tw_cluster *clusters;
};

static struct tw_box make_box(float x0, float y0, float z0, float x1, float y1, float z1)
{
    struct tw_box b = {{x0, y0, z0}, {x1, y1, z1}};
    return b;
}

static void proto_init(struct test_proto *tp, const char *name, uint32_t count)
{
    memset(tp, 0, sizeof(*tp));
    snprintf(tp->proto.name, sizeof(tp->proto.name), "%s", name);
    tp->proto.weight = 1.0f;
    tp->clusters = calloc(count ? count : 1, sizeof(*tp->clusters));
    if (!tp->clusters) {
        fprintf(stderr, "out of memory\n");
        exit(1);
    }
    tp->proto.clusters = tp->clusters;
    tp->proto.cluster_count = count;
}

static void proto_set(struct test_proto *tp, uint32_t i, struct tw_box box, uint32_t triangles)
{
    tp->clusters[i].instance = i;
    tp->clusters[i].part = i;
    tp->clusters[i].triangle_count = triangles;
    tp->clusters[i].box = box;
}

static void proto_seal(struct test_proto *tp)
{
    tp->proto.box = tw_box_empty();
    tp->proto.triangle_count = 0;
    for (uint32_t i = 0; i < tp->proto.cluster_count; i++) {
        tw_box_add_box(&tp->proto.box, &tp->clusters[i].box);
        tp->proto.triangle_count += tp->clusters[i].triangle_count;
    }
}

static void proto_finish(struct test_proto *tp)
{
    free(tp->clusters);
    memset(tp, 0, sizeof(*tp));
}

static uint64_t rng_state;

static uint32_t rng(void)
{
    /* xorshift64*: deterministic across platforms. */
    rng_state ^= rng_state >> 12;
    rng_state ^= rng_state << 25;
    rng_state ^= rng_state >> 27;
    return (uint32_t)((rng_state * 2685821657736338717ull) >> 32);
}

static float rngf(float lo, float hi)
{
    return lo + (hi - lo) * (float)(rng() >> 8) / (float)(1u << 24);
}

/* A city-like block: buildings of stacked boxes (floors, ledges) plus small
 * street furniture, so that sizes and triangle counts vary a lot. */
static void make_synthetic(struct test_proto *tp, const char *name, uint64_t seed,
                           uint32_t count, int clustered)
{
    rng_state = seed * 0x9E3779B97F4A7C15ull + 1;
    proto_init(tp, name, count);
    uint32_t i = 0;
    while (i < count) {
        if (!clustered) {
            const float x = rngf(0, 80), y = rngf(0, 30), z = rngf(0, 80);
            proto_set(tp, i++, make_box(x, y, z, x + rngf(0.1f, 8), y + rngf(0.1f, 8),
                                        z + rngf(0.1f, 8)),
                      1 + rng() % 2048);
            continue;
        }
        const float x = rngf(7, 65), z = rngf(7, 65), w = rngf(4, 15), d = rngf(4, 15);
        const uint32_t floors = 1 + rng() % 30;
        for (uint32_t f = 0; f < floors && i < count; f++) {
            const float y = 3.0f * (float)f;
            proto_set(tp, i++, make_box(x, y, z, x + w, y + 3.0f, z + d), 64 + rng() % 1024);
        }
        if (i < count) {
            const float px = rngf(0, 80), pz = rngf(0, 80);
            proto_set(tp, i++, make_box(px, 0, pz, px + 0.3f, 4, pz + 0.3f), 12);
        }
    }
    proto_seal(tp);
}

/* ---- checks ------------------------------------------------------------------ */

static bool box_equal(const struct tw_box *a, const struct tw_box *b)
{
    return memcmp(a, b, sizeof(*a)) == 0;
}

static bool is_leaf(const struct tw_bvh_node *n)
{
    return n->child[0] == TW_BVH_NONE;
}

/* The tight-box frontier of node, as DESIGN §7 defines it, by recursion
 * (independent of the iterative walk in bvh.c). */
static void frontier(const struct tw_bvh *bvh, uint32_t node, uint32_t levels,
                     struct tw_box *out, uint32_t *count, double *area)
{
    const struct tw_bvh_node *n = &bvh->nodes[node];
    if (is_leaf(n) || levels == 0) {
        out[(*count)++] = n->box;
        *area += tw_box_surface_area(&n->box);
        return;
    }
    frontier(bvh, n->child[0], levels - 1, out, count, area);
    frontier(bvh, n->child[1], levels - 1, out, count, area);
}

/* Everything a built BVH must satisfy for these settings, beyond validate. */
static void check_bvh(const struct tw_bvh *bvh, const struct tw_prototype *proto,
                      const struct tw_bvh_settings *s_in, const char *what)
{
    struct tw_bvh_settings s = s_in ? *s_in : (struct tw_bvh_settings){0};
    tw_bvh_default_settings(&s);
    char why[256];

    int r = tw_bvh_validate(bvh, proto, s.max_depth, why, sizeof(why));
    CHECK_MSG(r == TW_OK, "%s '%s': validate: %s", what, proto->name, why);
    if (r != TW_OK)
        return;

    CHECK_MSG(bvh->depth <= s.max_depth, "%s: depth %u > %u", what, bvh->depth, s.max_depth);
    /* A packed tree's pieces start at multiples of 16 bytes in its block. */
#define PIECE(n) (bvh->packed ? ((uint64_t)(n) + 15u) / 16u * 16u : (uint64_t)(n))
    const uint64_t bytes = PIECE(sizeof(*bvh)) + PIECE(bvh->node_count * sizeof(*bvh->nodes)) +
                           PIECE(bvh->cluster_count * sizeof(uint32_t)) +
                           PIECE(bvh->tight_box_count * sizeof(struct tw_box));
#undef PIECE
    CHECK_MSG(bvh->bytes == bytes, "%s: bytes %llu, expected %llu", what,
              (unsigned long long)bvh->bytes, (unsigned long long)bytes);
    CHECK_MSG(bvh->build_ms >= 0.0, "%s: negative build time", what);
    CHECK_MSG(bvh->nodes[0].triangle_count == proto->triangle_count,
              "%s: root has %u triangles, prototype %llu", what, bvh->nodes[0].triangle_count,
              (unsigned long long)proto->triangle_count);

    struct tw_box *list = malloc((size_t)bvh->node_count * sizeof(*list));
    if (!list) {
        fprintf(stderr, "out of memory\n");
        exit(1);
    }
    uint32_t tight_total = 0;
    for (uint32_t i = 0; i < bvh->node_count; i++) {
        const struct tw_bvh_node *n = &bvh->nodes[i];

        /* Tight node boxes: exactly the union of what lies below. */
        struct tw_box u = tw_box_empty();
        if (is_leaf(n)) {
            for (uint32_t k = 0; k < n->cluster_count; k++)
                tw_box_add_box(&u, &proto->clusters[bvh->cluster_order[n->first_cluster + k]].box);
        } else {
            tw_box_add_box(&u, &bvh->nodes[n->child[0]].box);
            tw_box_add_box(&u, &bvh->nodes[n->child[1]].box);
        }
        CHECK_MSG(box_equal(&u, &n->box), "%s: node %u's box is not tight", what, i);

        /* Leaf rules: a leaf holds one cluster unless the depth limit or the
         * triangle floor made it; an interior node is above both. */
        if (is_leaf(n)) {
            CHECK_MSG(n->cluster_count == 1 || n->depth == s.max_depth ||
                      n->triangle_count < s.min_leaf_triangles,
                      "%s: leaf %u holds %u clusters at depth %u with %u triangles", what, i,
                      n->cluster_count, n->depth, n->triangle_count);
        } else {
            CHECK_MSG(n->depth < s.max_depth, "%s: interior node %u at the depth limit", what, i);
            CHECK_MSG(n->triangle_count >= s.min_leaf_triangles,
                      "%s: interior node %u has %u triangles < %u", what, i, n->triangle_count,
                      s.min_leaf_triangles);
        }

        /* Tight-box lists: the frontier when its area passes the rule. */
        uint32_t count = 0;
        double area = 0.0;
        frontier(bvh, i, s.tight_depth, list, &count, &area);
        const double own = tw_box_surface_area(&n->box);
        const bool use = count > 1 && area <= (double)s.tight_area_ratio * own;
        CHECK_MSG(n->tight_count == (use ? count : 1), "%s: node %u has %u tight boxes, expected %u",
                  what, i, n->tight_count, use ? count : 1);
        CHECK_MSG(n->first_tight == tight_total, "%s: node %u's tight boxes are not packed", what, i);
        if (n->tight_count == (use ? count : 1)) {
            const struct tw_box *got = &bvh->tight_boxes[n->first_tight];
            if (use) {
                for (uint32_t k = 0; k < count; k++)
                    CHECK_MSG(box_equal(&got[k], &list[k]), "%s: node %u tight box %u differs", what,
                              i, k);
            } else {
                CHECK_MSG(box_equal(got, &n->box), "%s: node %u's single tight box is not its own",
                          what, i);
            }
        }
        tight_total += n->tight_count;
    }
    CHECK_MSG(tight_total == bvh->tight_box_count, "%s: %u tight boxes listed, %u stored", what,
              tight_total, bvh->tight_box_count);
    free(list);
}

/* ---- hand-made structure tests ----------------------------------------------- */

struct log_capture {
    int messages;
    char last[256];
};

static void capture(void *user, enum tw_log_level level, const char *msg)
{
    struct log_capture *c = user;
    (void)level;
    c->messages++;
    snprintf(c->last, sizeof(c->last), "%s", msg);
}

static void test_errors(struct tw_bvh_builder *b, struct log_capture *cap)
{
    struct test_proto tp;
    struct tw_bvh *bvh = (struct tw_bvh *)&tp; /* must be reset to NULL on failure */

    proto_init(&tp, "empty", 0);
    const int before = cap->messages;
    CHECK_MSG(tw_bvh_build(b, &tp.proto, NULL, &bvh) == TW_ERR_INVALID, "zero clusters accepted");
    CHECK_MSG(bvh == NULL, "*out not reset on failure");
    CHECK_MSG(cap->messages > before && strstr(cap->last, "empty"),
              "no logged message naming the prototype: '%s'", cap->last);
    CHECK_MSG(tw_bvh_build_median(&tp.proto, NULL, &bvh) == TW_ERR_INVALID,
              "median: zero clusters accepted");
    proto_finish(&tp);

    proto_init(&tp, "inverted", 2);
    proto_set(&tp, 0, make_box(0, 0, 0, 1, 1, 1), 2);
    proto_set(&tp, 1, make_box(2, 2, 2, 1, 1, 1), 2);
    proto_seal(&tp);
    CHECK_MSG(tw_bvh_build(b, &tp.proto, NULL, &bvh) == TW_ERR_INVALID, "empty cluster box accepted");
    tp.clusters[1].box = make_box(0, 0, 0, NAN, 1, 1);
    CHECK_MSG(tw_bvh_build(b, &tp.proto, NULL, &bvh) == TW_ERR_INVALID, "NaN cluster box accepted");
    tp.clusters[1].box = make_box(0, 0, 0, 1, 1, 1);
    struct tw_bvh_settings s = {.tight_area_ratio = -1.0f};
    CHECK_MSG(tw_bvh_build(b, &tp.proto, &s, &bvh) == TW_ERR_INVALID, "negative ratio accepted");
    CHECK_MSG(tw_bvh_build(NULL, &tp.proto, NULL, &bvh) == TW_ERR_INVALID, "NULL builder accepted");
    CHECK_MSG(tw_bvh_build(b, NULL, NULL, &bvh) == TW_ERR_INVALID, "NULL prototype accepted");
    CHECK_MSG(tw_bvh_build(b, &tp.proto, NULL, NULL) == TW_ERR_INVALID, "NULL out accepted");
    proto_finish(&tp);

    tw_bvh_destroy(NULL);
    tw_bvh_builder_destroy(NULL);
    CHECK_MSG(tw_bvh_sah_cost(NULL) == 0.0, "cost of nothing");
    CHECK_MSG(tw_bvh_validate(NULL, NULL, 32, NULL, 0) == TW_ERR_STATE, "validate(NULL) passed");
}

static void test_one_cluster(struct tw_bvh_builder *b)
{
    struct test_proto tp;
    proto_init(&tp, "one", 1);
    proto_set(&tp, 0, make_box(1, 2, 3, 4, 5, 6), 100);
    proto_seal(&tp);

    for (int median = 0; median < 2; median++) {
        struct tw_bvh *bvh = NULL;
        const int r = median ? tw_bvh_build_median(&tp.proto, NULL, &bvh)
                             : tw_bvh_build(b, &tp.proto, NULL, &bvh);
        CHECK_MSG(r == TW_OK, "one cluster: build failed: %s", tw_error_to_str(r));
        if (r != TW_OK)
            continue;
        const struct tw_bvh_node *n = &bvh->nodes[0];
        CHECK_MSG(bvh->node_count == 1 && bvh->leaf_count == 1 && bvh->depth == 0,
                  "one cluster: %u nodes, %u leaves, depth %u", bvh->node_count, bvh->leaf_count,
                  bvh->depth);
        CHECK_MSG(is_leaf(n) && n->child[1] == TW_BVH_NONE && n->parent == TW_BVH_NONE,
                  "one cluster: root is not a lone leaf");
        CHECK_MSG(n->first_cluster == 0 && n->cluster_count == 1 && bvh->cluster_order[0] == 0,
                  "one cluster: wrong cluster range");
        CHECK_MSG(box_equal(&n->box, &tp.clusters[0].box), "one cluster: box differs");
        CHECK_MSG(n->tight_count == 1 && bvh->tight_box_count == 1 &&
                  box_equal(&bvh->tight_boxes[0], &n->box), "one cluster: tight list");
        CHECK_MSG(n->triangle_count == 100, "one cluster: %u triangles", n->triangle_count);
        CHECK_MSG(fabs(tw_bvh_sah_cost(bvh) - 100.0 / 64.0) < 1e-9, "one cluster: cost %g",
                  tw_bvh_sah_cost(bvh));
        check_bvh(bvh, &tp.proto, NULL, median ? "median one" : "sah one");
        tw_bvh_destroy(bvh);
    }
    proto_finish(&tp);
}

static void test_two_clusters(struct tw_bvh_builder *b)
{
    struct test_proto tp;
    proto_init(&tp, "two", 2);
    proto_set(&tp, 0, make_box(0, 0, 0, 1, 1, 1), 10);
    proto_set(&tp, 1, make_box(5, 0, 0, 6, 2, 1), 30);
    proto_seal(&tp);

    for (int median = 0; median < 2; median++) {
        struct tw_bvh *bvh = NULL;
        const int r = median ? tw_bvh_build_median(&tp.proto, NULL, &bvh)
                             : tw_bvh_build(b, &tp.proto, NULL, &bvh);
        CHECK_MSG(r == TW_OK, "two clusters: build failed: %s", tw_error_to_str(r));
        if (r != TW_OK)
            continue;
        CHECK_MSG(bvh->node_count == 3 && bvh->leaf_count == 2 && bvh->depth == 1,
                  "two clusters: %u nodes, %u leaves, depth %u", bvh->node_count, bvh->leaf_count,
                  bvh->depth);
        const struct tw_bvh_node *root = &bvh->nodes[0];
        CHECK_MSG(!is_leaf(root) && root->cluster_count == 0 && root->triangle_count == 40,
                  "two clusters: root");
        CHECK_MSG(box_equal(&root->box, &tp.proto.box), "two clusters: root box is not the union");
        uint32_t seen = 0;
        for (int k = 0; k < 2 && !is_leaf(root); k++) {
            const struct tw_bvh_node *leaf = &bvh->nodes[root->child[k]];
            CHECK_MSG(is_leaf(leaf) && leaf->cluster_count == 1 && leaf->parent == 0 &&
                      leaf->depth == 1, "two clusters: child %d is not a leaf under the root", k);
            const uint32_t c = bvh->cluster_order[leaf->first_cluster];
            seen |= 1u << c;
            CHECK_MSG(box_equal(&leaf->box, &tp.clusters[c].box), "two clusters: leaf box");
            CHECK_MSG(leaf->triangle_count == tp.clusters[c].triangle_count, "two clusters: leaf tris");
        }
        CHECK_MSG(seen == 3, "two clusters: leaves hold clusters mask %u", seen);
        /* The leaves' areas (6 + 10) are below 1.4 x the root's 40. */
        CHECK_MSG(root->tight_count == 2, "two clusters: root should use its children as tight boxes");
        /* Cost: root 1 + leaves 6/40*10/64 + 10/40*30/64. */
        const double expect = 1.0 + (6.0 / 40.0) * 10.0 / 64.0 + (10.0 / 40.0) * 30.0 / 64.0;
        CHECK_MSG(fabs(tw_bvh_sah_cost(bvh) - expect) < 1e-6, "two clusters: cost %g, expected %g",
                  tw_bvh_sah_cost(bvh), expect);
        check_bvh(bvh, &tp.proto, NULL, median ? "median two" : "sah two");

        /* Corrupt a copy: validate must notice. */
        struct tw_bvh_node saved = bvh->nodes[1];
        char why[128];
        bvh->nodes[1].box.max[0] += 100.0f;
        CHECK_MSG(tw_bvh_validate(bvh, &tp.proto, 32, why, sizeof(why)) == TW_ERR_STATE,
                  "validate missed a child box outside its parent");
        bvh->nodes[1] = saved;
        bvh->cluster_order[1] = bvh->cluster_order[0];
        CHECK_MSG(tw_bvh_validate(bvh, &tp.proto, 32, why, sizeof(why)) == TW_ERR_STATE,
                  "validate missed a cluster in two leaves");
        CHECK_MSG(tw_bvh_validate(bvh, &tp.proto, 0, why, sizeof(why)) == TW_ERR_STATE,
                  "validate missed the depth limit");
        tw_bvh_destroy(bvh);
    }

    /* A floor above the whole prototype's triangles: one leaf of both. */
    struct tw_bvh_settings s = {.min_leaf_triangles = 41};
    struct tw_bvh *bvh = NULL;
    int r = tw_bvh_build(b, &tp.proto, &s, &bvh);
    CHECK_MSG(r == TW_OK && bvh->node_count == 1 && bvh->nodes[0].cluster_count == 2,
              "two clusters: min_leaf_triangles 41 should give one leaf");
    if (r == TW_OK)
        check_bvh(bvh, &tp.proto, &s, "sah two floor");
    tw_bvh_destroy(bvh);
    s.min_leaf_triangles = 40;
    r = tw_bvh_build(b, &tp.proto, &s, &bvh);
    CHECK_MSG(r == TW_OK && bvh->node_count == 3, "two clusters: min_leaf_triangles 40 splits");
    tw_bvh_destroy(bvh);
    proto_finish(&tp);
}

/* Two pairs of boxes far apart: SAH must pair the neighbours. */
static void test_two_pairs(struct tw_bvh_builder *b)
{
    struct test_proto tp;
    proto_init(&tp, "pairs", 4);
    proto_set(&tp, 0, make_box(0, 0, 0, 1, 1, 1), 5);
    proto_set(&tp, 1, make_box(100, 0, 0, 101, 1, 1), 5);
    proto_set(&tp, 2, make_box(1.5f, 0, 0, 2.5f, 1, 1), 5);
    proto_set(&tp, 3, make_box(101.5f, 0, 0, 102.5f, 1, 1), 5);
    proto_seal(&tp);

    struct tw_bvh *bvh = NULL;
    const int r = tw_bvh_build(b, &tp.proto, NULL, &bvh);
    CHECK_MSG(r == TW_OK, "pairs: build failed");
    if (r != TW_OK)
        return;
    CHECK_MSG(bvh->node_count == 7 && bvh->depth == 2 && bvh->leaf_count == 4,
              "pairs: %u nodes, depth %u", bvh->node_count, bvh->depth);
    const struct tw_bvh_node *root = &bvh->nodes[0];
    for (int k = 0; k < 2 && !is_leaf(root); k++) {
        const struct tw_bvh_node *pair = &bvh->nodes[root->child[k]];
        CHECK_MSG(pair->box.max[0] - pair->box.min[0] == 2.5f,
                  "pairs: child %d spans %g m, not one pair", k, pair->box.max[0] - pair->box.min[0]);
    }
    check_bvh(bvh, &tp.proto, NULL, "sah pairs");

    /* max_depth 1: the two pairs become two-cluster leaves. */
    struct tw_bvh_settings s = {.max_depth = 1};
    tw_bvh_destroy(bvh);
    bvh = NULL;
    CHECK_MSG(tw_bvh_build(b, &tp.proto, &s, &bvh) == TW_OK && bvh->node_count == 3 &&
              bvh->nodes[1].cluster_count == 2 && bvh->nodes[2].cluster_count == 2,
              "pairs: max_depth 1 should leave two leaves of two");
    if (bvh)
        check_bvh(bvh, &tp.proto, &s, "sah pairs depth 1");
    tw_bvh_destroy(bvh);
    proto_finish(&tp);
}

/* ---- prototypes at scale ---------------------------------------------------- */

static void print_header(void)
{
    printf("%-20s %8s %7s %5s %9s %10s %12s %9s %9s %8s\n", "prototype", "clusters", "nodes",
           "depth", "build_ms", "bytes", "clusters/s", "sah", "median", "ratio");
}

static void test_prototype(struct tw_bvh_builder *b, const struct tw_prototype *proto)
{
    struct tw_bvh *sah = NULL, *median = NULL;
    int r = tw_bvh_build(b, proto, NULL, &sah);
    CHECK_MSG(r == TW_OK, "'%s': build failed: %s", proto->name, tw_error_to_str(r));
    r = tw_bvh_build_median(proto, NULL, &median);
    CHECK_MSG(r == TW_OK, "'%s': median build failed: %s", proto->name, tw_error_to_str(r));
    if (!sah || !median)
        goto out;

    check_bvh(sah, proto, NULL, "sah");
    check_bvh(median, proto, NULL, "median");
    /* Median splits are balanced: depth ceil(log2 n) under the default 32. */
    uint32_t balanced = 0;
    while ((1ull << balanced) < proto->cluster_count)
        balanced++;
    CHECK_MSG(median->depth == (balanced < 32 ? balanced : 32),
              "'%s': median tree depth %u, expected %u", proto->name, median->depth, balanced);
    const double sah_cost = tw_bvh_sah_cost(sah), median_cost = tw_bvh_sah_cost(median);
    if (proto->cluster_count > 2)
        CHECK_MSG(sah_cost < median_cost, "'%s': SAH cost %g not below median split's %g",
                  proto->name, sah_cost, median_cost);

    printf("%-20.20s %8u %7u %5u %9.3f %10llu %12.0f %9.3f %9.3f %8.3f\n", proto->name,
           proto->cluster_count, sah->node_count, sah->depth, sah->build_ms,
           (unsigned long long)sah->bytes,
           sah->build_ms > 0 ? proto->cluster_count / (sah->build_ms * 1e-3) : 0.0, sah_cost,
           median_cost, sah_cost / median_cost);

    /* Embree's build is deterministic: the same input gives the same tree. */
    struct tw_bvh *again = NULL;
    if (tw_bvh_build(b, proto, NULL, &again) == TW_OK) {
        CHECK_MSG(again->node_count == sah->node_count &&
                  memcmp(again->nodes, sah->nodes, sah->node_count * sizeof(*sah->nodes)) == 0 &&
                  memcmp(again->cluster_order, sah->cluster_order,
                         sah->cluster_count * sizeof(uint32_t)) == 0,
                  "'%s': two builds differ", proto->name);
    }
    /* Packed into one block, the tree is the same (check_bvh checks its
     * bytes, the block's). */
    if (again && tw_bvh_pack(&again) == TW_OK) {
        check_bvh(again, proto, NULL, "packed");
        CHECK_MSG(again->node_count == sah->node_count && again->depth == sah->depth &&
                  again->leaf_count == sah->leaf_count &&
                  memcmp(again->nodes, sah->nodes, sah->node_count * sizeof(*sah->nodes)) == 0 &&
                  memcmp(again->cluster_order, sah->cluster_order,
                         sah->cluster_count * sizeof(uint32_t)) == 0 &&
                  again->tight_box_count == sah->tight_box_count &&
                  memcmp(again->tight_boxes, sah->tight_boxes,
                         sah->tight_box_count * sizeof(*sah->tight_boxes)) == 0,
                  "'%s': the packed tree differs", proto->name);
    } else {
        CHECK_MSG(0, "'%s': cannot pack", proto->name);
    }
    tw_bvh_destroy(again);

    /* Leaf rules under tighter settings, for both builders. */
    const uint32_t floor_tris = (uint32_t)(proto->triangle_count / 16);
    const struct tw_bvh_settings variants[] = {
        {.max_depth = 3},
        {.min_leaf_triangles = floor_tris > 0 ? floor_tris : 1},
        {.max_depth = 5, .min_leaf_triangles = floor_tris / 4 + 1},
        {.tight_depth = 1, .tight_area_ratio = 100.0f},
        {.tight_depth = 6, .tight_area_ratio = 0.5f},
    };
    for (size_t v = 0; v < sizeof(variants) / sizeof(variants[0]); v++) {
        struct tw_bvh *t = NULL, *m = NULL;
        CHECK_MSG(tw_bvh_build(b, proto, &variants[v], &t) == TW_OK, "'%s': variant %zu failed",
                  proto->name, v);
        CHECK_MSG(tw_bvh_build_median(proto, &variants[v], &m) == TW_OK,
                  "'%s': median variant %zu failed", proto->name, v);
        if (t)
            check_bvh(t, proto, &variants[v], "sah variant");
        if (m)
            check_bvh(m, proto, &variants[v], "median variant");
        if (t && variants[v].max_depth)
            CHECK_MSG(t->depth <= variants[v].max_depth, "'%s': depth %u over %u", proto->name,
                      t->depth, variants[v].max_depth);
        if (t && v == 3) {
            /* Ratio 100 at depth 1: every interior node lists its children. */
            for (uint32_t i = 0; i < t->node_count; i++)
                CHECK_MSG(t->nodes[i].tight_count == (is_leaf(&t->nodes[i]) ? 1u : 2u),
                          "'%s': node %u tight count %u with ratio 100", proto->name, i,
                          t->nodes[i].tight_count);
        }
        tw_bvh_destroy(t);
        tw_bvh_destroy(m);
    }

out:
    tw_bvh_destroy(sah);
    tw_bvh_destroy(median);
}

int main(void)
{
    struct log_capture cap = {0};
    struct tw_log log = {capture, &cap};
    struct tw_bvh_builder *b = NULL;
    int r = tw_bvh_builder_create(&log, 0, &b);
    if (r != TW_OK) {
        fprintf(stderr, "test-bvh: cannot create a builder: %s (%s)\n", tw_error_to_str(r),
                cap.last);
        return 1;
    }

    test_errors(b, &cap);
    test_one_cluster(b);
    test_two_clusters(b);
    test_two_pairs(b);

    print_header();
    struct test_proto tp;
    static const struct {
        const char *name;
        uint32_t count;
        int clustered;
    } synthetic[] = {
        {"synthetic-uniform", 300, 0},
        {"synthetic-blocks", 600, 1},
        {"synthetic-large", 4000, 1},
    };
    for (size_t i = 0; i < sizeof(synthetic) / sizeof(synthetic[0]); i++) {
        make_synthetic(&tp, synthetic[i].name, i + 1, synthetic[i].count, synthetic[i].clustered);
        test_prototype(b, &tp.proto);
        proto_finish(&tp);
    }

    struct tw_tileset *ts = NULL;
    r = tw_tilesets_builtin("city", 1, 0, NULL, &ts);
    CHECK_MSG(r == TW_OK && ts, "city tileset: %s", tw_error_to_str(r));
    for (uint32_t p = 0; ts && p < ts->prototype_count; p++)
        test_prototype(b, &ts->prototypes[p]);
    tw_tileset_destroy(ts);

    tw_bvh_builder_destroy(b);
    return check_summary("test-bvh");
}
