/*
 * The cost calibration of DESIGN §14: what a query, a draw call and a
 * triangle cost on the GPU a world draws with, measured when the world is
 * created. Private to runtime/.
 */
#ifndef TW_RUNTIME_CALIBRATE_H
#define TW_RUNTIME_CALIBRATE_H

#include "runtime/renderer.h"
#include "runtime/runtime-internal.h"

/* Figures for a world whose counts must not depend on timing
 * (tw_world_settings.deterministic): llvmpipe's, measured on two cores. */
void tw_calibrate_nominal(struct tw_calibration *out);

/* Measures out (about a tenth of a second), each figure the median of five
 * rounds: queries of one small box read back one by one (the round trip),
 * in a batch (a query's own cost; the difference is what a batch adds
 * once), of one large box and of eight small boxes (a box, a pixel); draws
 * of a hidden cluster, every fragment failing the depth test, as a node
 * drawn without the query that would have found it hidden: the smallest
 * cluster of ts and its largest of at most 512 triangles far away (the
 * call, a triangle), the latter near, covering about a sixteenth of the
 * image (a pixel of its box's screen rectangle). ts is uploaded with
 * prototype p as content first_content + p (NULL: the draw figures stay
 * nominal); each batch is warmed up first and closed by glFinish, timed in
 * process CPU time. r must be entered (tw_renderer_enter); its frame is
 * left cleared. */
int tw_calibrate_measure(struct tw_renderer *r, const struct tw_tileset *ts,
                         uint32_t first_content, uint32_t width, uint32_t height, float fov_y,
                         struct tw_calibration *out);

/* The model CHC++ decides with: cal's figures for a width x height image. */
void tw_calibrate_model(const struct tw_calibration *cal, uint32_t width, uint32_t height,
                        struct tw_cost_model *out);

#endif
