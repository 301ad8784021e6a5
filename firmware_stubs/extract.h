/*
 * extract.h - pupil and glint extraction from one 8-bit infrared image (dark pupil, LED corneal reflections):
 * portable C99, no dynamic allocation, no library beyond <math.h>. The caller owns every buffer: the image
 * (read only, never kept) and an `ex_workspace` (static, about 250 kB with the default limits).
 *
 * Pipeline (one pass over the pixels, then work proportional to the features found):
 * 1. Classify each pixel: dark (< dark_max_dn: pupil), bright (>= bright_min_dn: glint), iris band
 *    (dark_max_dn .. iris_max_dn, counted for blink detection); dark and bright runs of each row are
 *    labelled into 8-connected regions (union-find over runs) with their area and first and second moments.
 * 2. Pupils: the dark regions of plausible area and shape, largest first; each one's moment ellipse seeds
 *    a sub-pixel edge search along `rays` rays from its centre: the first crossing of the local mid level
 *    (halfway between the pupil inside and the iris outside of that ray) found by linear interpolation of
 *    bilinear samples. Rays whose outside is not iris (an eyelid, the sclera, a glint) are rejected. A
 *    least-squares conic with A + C = 1 (invariant to rotation and translation), refitted twice without
 *    the points off it by more than 3 median residuals (at least `outlier_px`), gives the ellipse; a second
 *    round of rays from the fitted centre refines it.
 * 3. Glints: the bright regions up to `glint_max_area_px`, each one's centre the intensity-weighted centroid
 *    of (pixel - local background - glint_margin_dn) over its box widened by 3 px (the background is the
 *    mean of that box's border). Those within `glint_max_dist` pupil axes of a pupil are matched to the lit
 *    LEDs: the `n` closest to the pupil, ordered along the LEDs' layout (`led_dir_x/y`: each LED's direction
 *    from the camera's axis in image px, which the glints repeat, a convex mirror's image being upright).
 * 4. Blink: no pupil region and fewer than `blink_iris_px` iris-band pixels (the lids cover the eye).
 *
 * Coordinates: image px of the window, origin at the centre of the top-left pixel, x right, y down; the
 * caller adds the window's sensor origin. Angles in degrees of axis a from +x toward +y, [0, 180).
 */
#ifndef EH_EXTRACT_H
#define EH_EXTRACT_H

#include <stddef.h>
#include <stdint.h>

#ifndef EX_MAX_RUNS
#define EX_MAX_RUNS 16384u         /* dark + bright runs per image; more: the rest are ignored (EX_OVERFLOW) */
#endif
#ifndef EX_MAX_REGIONS
#define EX_MAX_REGIONS 256u        /* regions of each class kept per image */
#endif
#define EX_MAX_RAYS 128u
#define EX_MAX_EYES 2u
#define EX_MAX_LEDS 2u

/* Result flags of an eye (the wire's pupil flags where they match). */
#define EX_PUPIL_DETECTED 0x01u
#define EX_PUPIL_PARTIAL 0x02u     /* fewer than half of the rays found the pupil's edge (eyelid, border) */
#define EX_PUPIL_BLINK 0x08u
/* Glint flags (the wire's). */
#define EX_GLINT_VALID 0x01u
#define EX_GLINT_SATURATED 0x02u
#define EX_GLINT_ON_PUPIL_EDGE 0x04u
#define EX_GLINT_AMBIGUOUS 0x08u
/* Image-level flags. */
#define EX_OVERFLOW 0x01u          /* run or region table full: some pixels were not labelled */

typedef struct {
    const uint8_t *pixels;         /* row-major, `stride` bytes per row; read only */
    uint16_t width, height;
    size_t stride;
} ex_image;

typedef struct {
    uint8_t dark_max_dn;           /* pupil pixels are below this */
    uint8_t iris_max_dn;           /* iris band: dark_max_dn .. iris_max_dn - 1; an edge's outside must be there */
    uint8_t bright_min_dn;         /* glint pixels are at least this */
    uint8_t saturated_dn;          /* a glint reaching this is SATURATED */
    uint8_t glint_margin_dn;       /* subtracted (with the background) from glint weights: noise rejection */
    uint16_t pupil_min_area_px, glint_max_area_px;
    uint32_t blink_iris_px;        /* fewer iris-band pixels and no pupil: a blink */
    uint8_t rays;                  /* edge rays per round, <= EX_MAX_RAYS */
    float outlier_px;              /* edge points farther than this (and 3 median residuals) are refitted out */
    float glint_max_dist;          /* glints within this many full pupil major axes of the pupil centre */
    float led_dir_x[EX_MAX_LEDS], led_dir_y[EX_MAX_LEDS]; /* image direction of each LED (its glint's side) */
} ex_params;

typedef struct {
    uint8_t led, flags;
    float x, y;                    /* px, meaningful with VALID */
} ex_glint;

typedef struct {
    uint8_t flags;                 /* EX_PUPIL_* */
    float cx, cy, axis_a, axis_b, angle_deg; /* ellipse: centre px, full axes a >= b px, angle */
    float confidence;              /* 0..1: share of edge rays used times fit quality */
    uint16_t edge_points;          /* points of the final fit */
    float fit_rms_px;              /* rms geometric residual of those points */
    uint8_t glint_count;           /* one per lit LED, in LED order */
    ex_glint glints[EX_MAX_LEDS];
} ex_eye;

typedef struct {
    uint8_t flags;                 /* EX_OVERFLOW */
    uint8_t eye_count;             /* dark regions taken as pupils (<= max_eyes), left to right; 0: see blink */
    uint8_t blink;                 /* 1: no pupil and the eye looks closed */
    uint32_t iris_px;              /* iris-band pixels */
    uint16_t dark_regions, bright_regions;
    ex_eye eyes[EX_MAX_EYES];
} ex_result;

/* A labelled region: pixel count, sums of x, y, x^2, xy, y^2 (px), bounding box (inclusive). */
typedef struct {
    double n, sx, sy, sxx, sxy, syy;
    uint16_t x0, y0, x1, y1;
} ex_region;

/* What one edge ray saw (see extract.c): direction, coarse edge radius px, levels inside and outside it and
 * the brightest sample just outside (DN), and whether it may be the pupil's edge. */
typedef struct {
    double c, s, r, v_in, v_out, v_max;
    int ok;
} ex_ray;

/* Work memory of ex_extract: runs, their union-find forest and the regions' sums. */
typedef struct {
    uint16_t run_y[EX_MAX_RUNS], run_x0[EX_MAX_RUNS], run_x1[EX_MAX_RUNS]; /* [x0, x1) */
    int32_t parent[EX_MAX_RUNS];
    int16_t region_of[EX_MAX_RUNS];
    uint8_t run_bright[EX_MAX_RUNS];
    ex_region region[2][EX_MAX_REGIONS]; /* dark, bright */
    float edge_x[EX_MAX_RAYS], edge_y[EX_MAX_RAYS]; /* the last edge round's points (window px) */
    uint8_t edge_used[EX_MAX_RAYS];  /* kept by its fit */
    uint16_t edge_count;
    double ray_c[EX_MAX_RAYS], ray_s[EX_MAX_RAYS];
    ex_ray rays[EX_MAX_RAYS];
} ex_workspace;

/* Defaults for the project's renderer at exposure 1 (pupil 25, iris 95, sclera 165, skin 185 DN, glints
 * saturating 255), LEDs along image x: LED 0 toward +x when `led0_right`, else toward -x. */
void ex_default_params(ex_params *p, int led0_right);

/* Extract up to `max_eyes` pupils (largest first, reported left to right) and, per pupil, one glint per LED
 * whose bit is set in `lit_mask` (at most EX_MAX_LEDS LEDs). Returns 0, or -1 on bad arguments (the result
 * then reports nothing). Never reads outside the image; never allocates. */
int ex_extract(const ex_image *img, const ex_params *p, uint8_t lit_mask, uint8_t max_eyes, ex_workspace *ws,
               ex_result *out);

/* The ellipse (centre, full axes a >= b, angle of a in degrees [0, 180)) of the conic
 * A x^2 + B xy + C y^2 + D x + E y + F = 0; 0, or -1 if it is not a real ellipse. */
int ex_conic_to_ellipse(const double conic[6], double *cx, double *cy, double *a, double *b, double *angle_deg);

/* Least-squares conic with A + C = 1 through n >= 5 points; 0, or -1 if degenerate. */
int ex_fit_conic(const float *x, const float *y, const uint8_t *use, size_t n, double conic[6]);

#endif
