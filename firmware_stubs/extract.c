/*
 * extract.c - pupil and glint extraction from an 8-bit image (see extract.h for the method). C99, no
 * allocation: every table lives in the caller's ex_workspace; doubles for sums and fits, floats for outputs.
 */
#include "extract.h"

#include <math.h>
#include <string.h>

#define PI 3.14159265358979323846
#define DARK 0u
#define BRIGHT 1u
#define EDGE_GLINT_PX 4.0       /* a glint centre this close to the pupil ellipse is ON_PUPIL_EDGE */
#define MIN_EDGE_POINTS 8u      /* fewer: the moment ellipse is reported, with a low confidence */
#define COARSE_STEP 0.5
#define FINE_STEP 0.25
#define MIN_PARTIAL_RATIO 0.75  /* b / a of a fit on less than half the edge, else not trusted */
#define MAX_TRIES 8u            /* dark regions tried as pupils per image */
#define IRIS_SPREAD_DN 15.0    /* an edge's outside level within this of the median outside level */
#define LEVEL_OFFSET 3.0        /* px inside / outside the coarse edge where the two levels are read */

void ex_default_params(ex_params *p, int led0_right)
{
    memset(p, 0, sizeof *p);
    p->dark_max_dn = 60;
    p->iris_max_dn = 140;
    p->bright_min_dn = 230;
    p->saturated_dn = 255;
    p->glint_margin_dn = 8;
    p->pupil_min_area_px = 12;
    p->glint_max_area_px = 400;
    p->blink_iris_px = 40;
    p->rays = 64;
    p->outlier_px = 0.5f;
    p->glint_max_dist = 2.0f;
    p->led_dir_x[0] = led0_right ? 1.0f : -1.0f;
    p->led_dir_x[1] = -p->led_dir_x[0];
}

/* --- 1. runs and regions ---------------------------------------------------------------------------- */

static int32_t find(int32_t *parent, int32_t i)
{
    while (parent[i] != i) {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    return i;
}

static void unite(int32_t *parent, int32_t a, int32_t b)
{
    a = find(parent, a);
    b = find(parent, b);
    if (a < b)
        parent[b] = a;
    else if (b < a)
        parent[a] = b;
}

typedef struct {
    ex_workspace *ws;
    uint32_t count, prev_start, prev_end; /* runs; the previous row's are [prev_start, prev_end) */
    int overflow;
} labeller;

static void add_run(labeller *lb, uint8_t cls, uint16_t y, uint16_t x0, uint16_t x1)
{
    ex_workspace *ws = lb->ws;
    uint32_t r = lb->count;

    if (r >= EX_MAX_RUNS) {
        lb->overflow = 1;
        return;
    }
    ws->run_y[r] = y;
    ws->run_x0[r] = x0;
    ws->run_x1[r] = x1;
    ws->run_bright[r] = cls;
    ws->parent[r] = (int32_t)r;
    for (uint32_t q = lb->prev_start; q < lb->prev_end; q++) { /* 8-connected overlap with the row above */
        if (ws->run_bright[q] == cls && ws->run_x0[q] <= x1 && ws->run_x1[q] >= x0)
            unite(ws->parent, (int32_t)q, (int32_t)r);
    }
    lb->count++;
}

/* Sum of k^2 for k = 0 .. m - 1. */
static double sum_sq(double m)
{
    return (m - 1.0) * m * (2.0 * m - 1.0) / 6.0;
}

static void label(const ex_image *img, const ex_params *p, ex_workspace *ws, ex_result *out, uint16_t counts[2])
{
    labeller lb = {ws, 0, 0, 0, 0};
    const uint8_t dark = p->dark_max_dn, bright = p->bright_min_dn, iris = p->iris_max_dn;
    uint32_t iris_px = 0;

    for (uint16_t y = 0; y < img->height; y++) {
        const uint8_t *row = img->pixels + (size_t)y * img->stride;
        uint32_t row_start = lb.count;
        uint16_t x = 0;
        while (x < img->width) {
            uint8_t v = row[x];
            if (v < dark) {
                uint16_t x0 = x;
                do
                    x++;
                while (x < img->width && row[x] < dark);
                add_run(&lb, DARK, y, x0, x);
            } else if (v >= bright) {
                uint16_t x0 = x;
                do
                    x++;
                while (x < img->width && row[x] >= bright);
                add_run(&lb, BRIGHT, y, x0, x);
            } else {
                iris_px += v < iris;
                x++;
            }
        }
        lb.prev_start = row_start < EX_MAX_RUNS ? row_start : EX_MAX_RUNS;
        lb.prev_end = lb.count;
    }
    out->iris_px = iris_px;
    if (lb.overflow)
        out->flags |= EX_OVERFLOW;

    counts[0] = counts[1] = 0;
    for (uint32_t r = 0; r < lb.count; r++) {
        int32_t root = find(ws->parent, (int32_t)r);
        uint8_t cls = ws->run_bright[r];
        int16_t k;
        double n, x0, x1, y;
        if ((uint32_t)root == r) {
            if (counts[cls] >= EX_MAX_REGIONS) {
                ws->region_of[r] = -1;
                out->flags |= EX_OVERFLOW;
                continue;
            }
            ws->region_of[r] = (int16_t)counts[cls];
            memset(&ws->region[cls][counts[cls]], 0, sizeof ws->region[cls][0]);
            ws->region[cls][counts[cls]].x0 = ws->run_x0[r];
            ws->region[cls][counts[cls]].y0 = ws->run_y[r];
            ws->region[cls][counts[cls]].x1 = ws->run_x0[r];
            ws->region[cls][counts[cls]].y1 = ws->run_y[r];
            counts[cls]++;
        }
        k = ws->region_of[root]; /* roots come before their runs: index order */
        if (k < 0)
            continue;
        x0 = ws->run_x0[r];
        x1 = ws->run_x1[r];
        y = ws->run_y[r];
        n = x1 - x0;
        {
            double sx = n * (x0 + x1 - 1.0) / 2.0, sxx = sum_sq(x1) - sum_sq(x0);
            ex_region *g = &ws->region[cls][k];
            g->n += n;
            g->sx += sx;
            g->sy += n * y;
            g->sxx += sxx;
            g->sxy += sx * y;
            g->syy += n * y * y;
            if (ws->run_x0[r] < g->x0)
                g->x0 = ws->run_x0[r];
            if (ws->run_x1[r] - 1u > g->x1)
                g->x1 = (uint16_t)(ws->run_x1[r] - 1u);
            if (ws->run_y[r] > g->y1)
                g->y1 = ws->run_y[r];
        }
    }
    out->dark_regions = counts[0];
    out->bright_regions = counts[1];
}

/* --- 2. pupil: moments, edge rays, conic fit ---------------------------------------------------------- */

/* Bilinear sample at (x, y) px; -1 outside the image (with a one-pixel margin for the interpolation). */
static double sample(const ex_image *img, double x, double y)
{
    double fx, fy;
    int ix, iy;
    const uint8_t *p;

    if (!(x >= 0.0 && y >= 0.0 && x < (double)img->width - 1.0 && y < (double)img->height - 1.0))
        return -1.0;
    ix = (int)x;
    iy = (int)y;
    fx = x - ix;
    fy = y - iy;
    p = img->pixels + (size_t)iy * img->stride + (size_t)ix;
    return (1.0 - fy) * ((1.0 - fx) * p[0] + fx * p[1]) + fy * ((1.0 - fx) * p[img->stride] + fx * p[img->stride + 1]);
}

typedef struct {
    double cx, cy, a, b, angle; /* semi-axes a >= b px, angle rad */
} ellipse;

static ellipse moment_ellipse(const ex_region *g)
{
    ellipse e;
    double vx, vy, cxy, half_tr, d;

    e.cx = g->sx / g->n;
    e.cy = g->sy / g->n;
    vx = g->sxx / g->n - e.cx * e.cx + 1.0 / 12.0; /* + the variance of a pixel's own area */
    vy = g->syy / g->n - e.cy * e.cy + 1.0 / 12.0;
    cxy = g->sxy / g->n - e.cx * e.cy;
    half_tr = (vx + vy) / 2.0;
    d = sqrt((vx - vy) * (vx - vy) / 4.0 + cxy * cxy);
    e.a = 2.0 * sqrt(half_tr + d);
    e.b = 2.0 * sqrt(half_tr - d > 0.0 ? half_tr - d : 0.0);
    e.angle = 0.5 * atan2(2.0 * cxy, vx - vy);
    return e;
}

/* Radius of ellipse `e` along the direction `t` (rad) from its centre. */
static double radius_along(const ellipse *e, double t)
{
    double u = cos(t - e->angle) / e->a, v = sin(t - e->angle) / (e->b > 0.5 ? e->b : 0.5);
    return 1.0 / sqrt(u * u + v * v);
}

/* Mean of three samples along the ray at r, r + step, r + 2 step; -1 if any is outside. */
static double level3(const ex_image *img, double cx, double cy, double c, double s, double r, double step)
{
    double sum = 0.0;
    for (int i = 0; i < 3; i++) {
        double v = sample(img, cx + (r + i * step) * c, cy + (r + i * step) * s);
        if (v < 0.0)
            return -1.0;
        sum += v;
    }
    return sum / 3.0;
}

/* What one ray from the pupil centre saw: the coarse edge (first sample at or above the dark threshold), the
 * levels inside and outside it, and the brightest sample just outside. */
typedef ex_ray ray;

/* Coarse stage along the ray from (cx, cy) in direction (c, s), searched in [r_lo, r_hi]. */
static void coarse_ray(const ex_image *img, const ex_params *p, double cx, double cy, double r_lo, double r_hi,
                       ray *y)
{
    double r;

    y->ok = 0;
    for (r = r_lo; r <= r_hi; r += COARSE_STEP) {
        double v = sample(img, cx + r * y->c, cy + r * y->s);
        if (v < 0.0)
            return;
        if (v >= p->dark_max_dn)
            break;
    }
    if (r > r_hi || r < 2.0)
        return;
    y->r = r;
    y->v_in = level3(img, cx, cy, y->c, y->s, r - LEVEL_OFFSET > r * 0.4 ? r - LEVEL_OFFSET : r * 0.4, -0.5);
    y->v_out = level3(img, cx, cy, y->c, y->s, r + LEVEL_OFFSET, 0.5);
    y->v_max = 0.0;
    for (double q = r; q <= r + LEVEL_OFFSET + 1.5; q += COARSE_STEP) {
        double v = sample(img, cx + q * y->c, cy + q * y->s);
        if (v < 0.0)
            return;
        y->v_max = v > y->v_max ? v : y->v_max;
    }
    y->ok = y->v_in >= 0.0 && y->v_out >= 0.0 && y->v_in < p->dark_max_dn && y->v_out >= p->dark_max_dn
            && y->v_out < p->iris_max_dn && y->v_max < p->iris_max_dn;
}

/* Fine stage: the crossing of the ray's mid level near its coarse edge, by linear interpolation; 0 if none. */
static int fine_ray(const ex_image *img, double cx, double cy, const ray *y, double *r_edge)
{
    double level = (y->v_in + y->v_out) / 2.0, prev_r = y->r - 2.5, prev;

    prev = sample(img, cx + prev_r * y->c, cy + prev_r * y->s);
    for (double q = prev_r + FINE_STEP; q <= y->r + 2.5; q += FINE_STEP) {
        double v = sample(img, cx + q * y->c, cy + q * y->s);
        if (v < 0.0)
            return 0;
        if (prev >= 0.0 && prev < level && v >= level) {
            *r_edge = prev_r + (q - prev_r) * (level - prev) / (v - prev);
            return 1;
        }
        prev = v;
        prev_r = q;
    }
    return 0;
}

int ex_fit_conic(const float *x, const float *y, const uint8_t *use, size_t n, double conic[6])
{
    double mx = 0.0, my = 0.0, s = 0.0, m = 0.0, ata[5][6];
    double A, B, C, D, E, F, sol[5];

    for (size_t i = 0; i < n; i++) {
        if (use == NULL || use[i]) {
            mx += x[i];
            my += y[i];
            m += 1.0;
        }
    }
    if (m < 5.0)
        return -1;
    mx /= m;
    my /= m;
    for (size_t i = 0; i < n; i++)
        if (use == NULL || use[i])
            s += (x[i] - mx) * (x[i] - mx) + (y[i] - my) * (y[i] - my);
    s = sqrt(s / m);
    if (!(s > 1e-9))
        return -1;
    memset(ata, 0, sizeof ata);
    for (size_t i = 0; i < n; i++) { /* A (u^2 - v^2) + B uv + D u + E v + F = -v^2, C = 1 - A */
        double u, v, row[6];
        if (use != NULL && !use[i])
            continue;
        u = (x[i] - mx) / s;
        v = (y[i] - my) / s;
        row[0] = u * u - v * v;
        row[1] = u * v;
        row[2] = u;
        row[3] = v;
        row[4] = 1.0;
        row[5] = -v * v;
        for (int j = 0; j < 5; j++)
            for (int k = 0; k < 6; k++)
                ata[j][k] += row[j] * row[k];
    }
    for (int col = 0; col < 5; col++) { /* Gaussian elimination, partial pivoting */
        int piv = col;
        for (int r = col + 1; r < 5; r++)
            if (fabs(ata[r][col]) > fabs(ata[piv][col]))
                piv = r;
        if (fabs(ata[piv][col]) < 1e-12)
            return -1;
        if (piv != col)
            for (int k = 0; k < 6; k++) {
                double t = ata[col][k];
                ata[col][k] = ata[piv][k];
                ata[piv][k] = t;
            }
        for (int r = col + 1; r < 5; r++) {
            double f = ata[r][col] / ata[col][col];
            for (int k = col; k < 6; k++)
                ata[r][k] -= f * ata[col][k];
        }
    }
    for (int r = 4; r >= 0; r--) {
        double t = ata[r][5];
        for (int k = r + 1; k < 5; k++)
            t -= ata[r][k] * sol[k];
        sol[r] = t / ata[r][r];
    }
    A = sol[0];
    B = sol[1];
    C = 1.0 - A;
    D = sol[2];
    E = sol[3];
    F = sol[4];
    /* back to image px: u = (x - mx) / s, v = (y - my) / s */
    conic[0] = A / (s * s);
    conic[1] = B / (s * s);
    conic[2] = C / (s * s);
    conic[3] = (-2.0 * A * mx - B * my) / (s * s) + D / s;
    conic[4] = (-2.0 * C * my - B * mx) / (s * s) + E / s;
    conic[5] = (A * mx * mx + B * mx * my + C * my * my) / (s * s) - (D * mx + E * my) / s + F;
    return 0;
}

int ex_conic_to_ellipse(const double conic[6], double *cx, double *cy, double *a, double *b, double *angle_deg)
{
    double A = conic[0], B = conic[1], C = conic[2], D = conic[3], E = conic[4], F = conic[5];
    double det, x0, y0, f0, h, l_hi, l_lo, d, t;

    if (A + C < 0.0) {
        A = -A, B = -B, C = -C, D = -D, E = -E, F = -F;
    }
    det = 4.0 * A * C - B * B;
    if (!(det > 0.0))
        return -1;
    x0 = (-2.0 * C * D + B * E) / det;
    y0 = (-2.0 * A * E + B * D) / det;
    f0 = F + (D * x0 + E * y0) / 2.0;
    h = B / 2.0;
    d = sqrt((A - C) * (A - C) / 4.0 + h * h);
    l_hi = (A + C) / 2.0 + d;
    l_lo = (A + C) / 2.0 - d;
    if (!(f0 < 0.0) || !(l_lo > 0.0))
        return -1;
    *cx = x0;
    *cy = y0;
    *a = 2.0 * sqrt(-f0 / l_lo);
    *b = 2.0 * sqrt(-f0 / l_hi);
    t = 0.5 * atan2(2.0 * h, A - C) * 180.0 / PI + 90.0; /* the largest eigenvalue's axis, turned 90 deg */
    t = fmod(t, 180.0);
    if (t < 0.0)
        t += 180.0;
    *angle_deg = t;
    return 0;
}

/* Geometric distance (px, first order) of (x, y) from the conic. */
static double conic_distance(const double q[6], double x, double y)
{
    double f = q[0] * x * x + q[1] * x * y + q[2] * y * y + q[3] * x + q[4] * y + q[5];
    double gx = 2.0 * q[0] * x + q[1] * y + q[3], gy = q[1] * x + 2.0 * q[2] * y + q[4];
    double g = sqrt(gx * gx + gy * gy);
    return g > 0.0 ? fabs(f) / g : 1e9;
}

/* Median of n >= 1 values (sorts a copy of at most EX_MAX_RAYS). */
static double median(const double *v, size_t n)
{
    double t[EX_MAX_RAYS];
    memcpy(t, v, n * sizeof *t);
    for (size_t i = 1; i < n; i++) { /* insertion sort: n <= 128 */
        double x = t[i];
        size_t j = i;
        while (j > 0 && t[j - 1] > x) {
            t[j] = t[j - 1];
            j--;
        }
        t[j] = x;
    }
    return n % 2 ? t[n / 2] : 0.5 * (t[n / 2 - 1] + t[n / 2]);
}

/* One round: edge points on `rays` rays around `seed`, then the fit with two outlier passes. Returns the
 * points used (0 if the fit failed) and fills `fit` and the rms residual. */
static unsigned edge_round(const ex_image *img, const ex_params *p, ex_workspace *ws, const ellipse *seed,
                           double lo, double hi_scale, ellipse *fit, double *rms)
{
    unsigned rays = p->rays > EX_MAX_RAYS ? EX_MAX_RAYS : p->rays, n = 0, used = 0, n_out = 0;
    uint8_t use[EX_MAX_RAYS];
    double res[EX_MAX_RAYS], q[6], a, b, ang, cx, cy, iris;

    for (unsigned k = 0; k < rays; k++) {
        double t = 2.0 * PI * k / rays;
        ws->ray_c[k] = cos(t);
        ws->ray_s[k] = sin(t);
    }
    for (unsigned k = 0; k < rays; k++) { /* coarse edges; the iris level is the median outside level */
        ray y;
        double re = radius_along(seed, 2.0 * PI * k / rays);
        y.c = ws->ray_c[k];
        y.s = ws->ray_s[k];
        coarse_ray(img, p, seed->cx, seed->cy, lo * re, hi_scale * re + 6.0, &y);
        ws->rays[k] = y;
        if (y.ok)
            res[n_out++] = y.v_out;
    }
    iris = n_out ? median(res, n_out) : 0.0;
    for (unsigned k = 0; k < rays; k++) { /* a lid, the sclera or a glint close outside: not the pupil's edge */
        const ray *y = &ws->rays[k];
        double r;
        if (!y->ok || fabs(y->v_out - iris) > IRIS_SPREAD_DN || y->v_max > iris + 2.0 * IRIS_SPREAD_DN)
            continue;
        if (fine_ray(img, seed->cx, seed->cy, y, &r)) {
            ws->edge_x[n] = (float)(seed->cx + r * y->c);
            ws->edge_y[n] = (float)(seed->cy + r * y->s);
            use[n++] = 1;
        }
    }
    if (n < MIN_EDGE_POINTS)
        return 0;
    for (int pass = 0; pass < 3; pass++) {
        double cut, med;
        unsigned m = 0;
        if (ex_fit_conic(ws->edge_x, ws->edge_y, use, n, q) != 0)
            return 0;
        if (pass == 2)
            break;
        for (unsigned i = 0; i < n; i++)
            res[i] = conic_distance(q, ws->edge_x[i], ws->edge_y[i]);
        med = median(res, n);
        cut = 3.0 * med > p->outlier_px ? 3.0 * med : p->outlier_px;
        for (unsigned i = 0; i < n; i++) {
            use[i] = res[i] <= cut;
            m += use[i];
        }
        if (m < MIN_EDGE_POINTS)
            return 0;
    }
    if (ex_conic_to_ellipse(q, &cx, &cy, &a, &b, &ang) != 0)
        return 0;
    *rms = 0.0;
    for (unsigned i = 0; i < n; i++) {
        if (use[i]) {
            double d = conic_distance(q, ws->edge_x[i], ws->edge_y[i]);
            *rms += d * d;
            used++;
        }
    }
    *rms = sqrt(*rms / used);
    memcpy(ws->edge_used, use, n);
    ws->edge_count = (uint16_t)n;
    fit->cx = cx;
    fit->cy = cy;
    fit->a = a / 2.0;
    fit->b = b / 2.0;
    fit->angle = ang * PI / 180.0;
    return used;
}

/* The pupil of dark region g: 1 if found (eye filled), 0 if the region is no pupil. */
static int pupil_of(const ex_image *img, const ex_params *p, ex_workspace *ws, const ex_region *g, ex_eye *eye)
{
    ellipse m = moment_ellipse(g), fit = m, fit2;
    double rms = 0.0, rms2 = 0.0, ang;
    unsigned rays = p->rays > EX_MAX_RAYS ? EX_MAX_RAYS : p->rays, used, used2;

    if (m.a < 1.5 || g->n < 0.5 * PI * m.a * m.b) /* too small, or far from filling its ellipse */
        return 0;
    memset(eye, 0, sizeof *eye);
    used = edge_round(img, p, ws, &m, 0.4, 1.6, &fit, &rms);
    if (used > 0) {
        used2 = edge_round(img, p, ws, &fit, 0.6, 1.3, &fit2, &rms2); /* again from the fitted centre */
        if (used2 > 0) {
            fit = fit2;
            rms = rms2;
            used = used2;
        }
    }
    if (used > 0 && (fit.a > 1.5 * m.a + 2.0 || fit.b < 0.5 * fit.a)) /* a short arc extrapolated wildly */
        used = 0;
    if (2u * used < rays && fit.b < MIN_PARTIAL_RATIO * fit.a) /* a pupil seen <= 40 deg off axis is rounder */
        used = 0;
    eye->flags = EX_PUPIL_DETECTED;
    if (4u * used < rays) { /* too little edge (lids): the region's moments, not a detection */
        fit = m;
        eye->confidence = 0.1f;
        eye->flags = EX_PUPIL_PARTIAL;
    } else {
        double share = (double)used / rays;
        eye->confidence = (float)(share / (1.0 + rms / 0.25));
        if (2u * used < rays)
            eye->flags |= EX_PUPIL_PARTIAL;
    }
    eye->cx = (float)fit.cx;
    eye->cy = (float)fit.cy;
    eye->axis_a = (float)(2.0 * fit.a);
    eye->axis_b = (float)(2.0 * fit.b);
    ang = fmod(fit.angle * 180.0 / PI, 180.0);
    eye->angle_deg = (float)(ang < 0.0 ? ang + 180.0 : ang);
    if (eye->angle_deg >= 180.0f)
        eye->angle_deg = 0.0f;
    eye->edge_points = (uint16_t)used;
    eye->fit_rms_px = (float)rms;
    return 1;
}

/* --- 3. glints --------------------------------------------------------------------------------------- */

typedef struct {
    double x, y;
    uint8_t saturated;
} glint_spot;

/* Intensity-weighted centroid of bright region g over its box widened by 3 px; 0 if it has no weight. */
static int glint_centroid(const ex_image *img, const ex_params *p, const ex_region *g, glint_spot *out)
{
    int x0 = g->x0 - 3, y0 = g->y0 - 3, x1 = g->x1 + 3, y1 = g->y1 + 3;
    double border = 0.0, nb = 0.0, sw = 0.0, sx = 0.0, sy = 0.0, floor_dn;
    uint8_t peak = 0;

    x0 = x0 < 0 ? 0 : x0;
    y0 = y0 < 0 ? 0 : y0;
    x1 = x1 >= img->width ? img->width - 1 : x1;
    y1 = y1 >= img->height ? img->height - 1 : y1;
    for (int y = y0; y <= y1; y++) {
        const uint8_t *row = img->pixels + (size_t)y * img->stride;
        for (int x = x0; x <= x1; x++) {
            if (row[x] > peak)
                peak = row[x];
            if (y == y0 || y == y1 || x == x0 || x == x1) {
                border += row[x];
                nb += 1.0;
            }
        }
    }
    floor_dn = border / nb + p->glint_margin_dn;
    for (int y = y0; y <= y1; y++) {
        const uint8_t *row = img->pixels + (size_t)y * img->stride;
        for (int x = x0; x <= x1; x++) {
            double w = row[x] - floor_dn;
            if (w > 0.0) {
                sw += w;
                sx += w * x;
                sy += w * y;
            }
        }
    }
    if (!(sw > 0.0))
        return 0;
    out->x = sx / sw;
    out->y = sy / sw;
    out->saturated = peak >= p->saturated_dn;
    return 1;
}

/* Distance (px, approximate) of (x, y) from the boundary of the pupil ellipse of `eye`. */
static double from_pupil_edge(const ex_eye *eye, double x, double y)
{
    double t = eye->angle_deg * PI / 180.0, dx = x - eye->cx, dy = y - eye->cy;
    double u = dx * cos(t) + dy * sin(t), v = -dx * sin(t) + dy * cos(t);
    double a = eye->axis_a / 2.0, b = eye->axis_b / 2.0 > 0.5 ? eye->axis_b / 2.0 : 0.5;
    double rho = sqrt(u * u / (a * a) + v * v / (b * b)), d = sqrt(dx * dx + dy * dy);
    return rho > 0.0 ? fabs(d - d / rho) : a;
}

/* Match the glint spots near the pupil of `eye` to the lit LEDs (see extract.h). */
static void match_glints(const ex_params *p, const glint_spot *spots, unsigned n_spots, uint8_t lit_mask,
                         ex_eye *eye)
{
    unsigned leds[EX_MAX_LEDS], n_lit = 0, pick[EX_MAX_LEDS], n_pick = 0;
    double reach = p->glint_max_dist * eye->axis_a, dist[EX_MAX_LEDS];

    for (unsigned i = 0; i < EX_MAX_LEDS; i++)
        if (lit_mask & (1u << i))
            leds[n_lit++] = i;
    eye->glint_count = (uint8_t)n_lit;
    for (unsigned i = 0; i < n_lit; i++) {
        eye->glints[i].led = (uint8_t)leds[i];
        eye->glints[i].flags = 0;
        eye->glints[i].x = eye->glints[i].y = 0.0f;
    }
    if (reach < 10.0)
        reach = 10.0;
    for (unsigned s = 0; s < n_spots; s++) { /* the n_lit spots closest to the pupil centre, within reach */
        double d = hypot(spots[s].x - eye->cx, spots[s].y - eye->cy);
        unsigned j;
        if (d > reach)
            continue;
        if (n_pick < n_lit) {
            j = n_pick++;
        } else {
            j = 0;
            for (unsigned k = 1; k < n_pick; k++)
                if (dist[k] > dist[j])
                    j = k;
            if (d >= dist[j])
                continue;
        }
        pick[j] = s;
        dist[j] = d;
    }
    if (n_pick < n_lit) {
        if (n_pick > 0) /* fewer reflections than LEDs: which LED made it is not known */
            for (unsigned i = 0; i < n_lit; i++)
                eye->glints[i].flags = EX_GLINT_AMBIGUOUS;
        return;
    }
    if (n_lit == 2) { /* order along the LEDs' layout */
        double lx = p->led_dir_x[leds[1]] - p->led_dir_x[leds[0]], ly = p->led_dir_y[leds[1]] - p->led_dir_y[leds[0]];
        double p0 = spots[pick[0]].x * lx + spots[pick[0]].y * ly, p1 = spots[pick[1]].x * lx + spots[pick[1]].y * ly;
        if (p0 > p1) {
            unsigned t = pick[0];
            pick[0] = pick[1];
            pick[1] = t;
        }
    }
    for (unsigned i = 0; i < n_lit; i++) {
        const glint_spot *s = &spots[pick[i]];
        ex_glint *gl = &eye->glints[i];
        gl->x = (float)s->x;
        gl->y = (float)s->y;
        gl->flags = EX_GLINT_VALID;
        if (s->saturated)
            gl->flags |= EX_GLINT_SATURATED;
        if (from_pupil_edge(eye, s->x, s->y) < EDGE_GLINT_PX)
            gl->flags |= EX_GLINT_ON_PUPIL_EDGE;
    }
}

/* --- 4. the whole image ------------------------------------------------------------------------------ */

int ex_extract(const ex_image *img, const ex_params *p, uint8_t lit_mask, uint8_t max_eyes, ex_workspace *ws,
               ex_result *out)
{
    uint16_t counts[2];
    unsigned tried[MAX_TRIES], n_found = 0, n_spots = 0;
    glint_spot spots[EX_MAX_REGIONS];

    memset(out, 0, sizeof *out);
    if (img == NULL || p == NULL || ws == NULL || img->pixels == NULL || img->width < 4 || img->height < 4 ||
        img->stride < img->width || max_eyes > EX_MAX_EYES || (lit_mask >> EX_MAX_LEDS) != 0)
        return -1;
    label(img, p, ws, out, counts);

    for (unsigned k = 0; k < counts[BRIGHT]; k++) {
        const ex_region *g = &ws->region[BRIGHT][k];
        if (g->n <= p->glint_max_area_px && glint_centroid(img, p, g, &spots[n_spots]))
            n_spots++;
    }
    while (out->eye_count < max_eyes && n_found < MAX_TRIES) { /* the largest plausible dark regions */
        int best = -1;
        for (unsigned k = 0; k < counts[DARK]; k++) {
            const ex_region *g = &ws->region[DARK][k];
            int taken = 0;
            for (unsigned i = 0; i < n_found; i++)
                taken |= tried[i] == k;
            if (!taken && g->n >= p->pupil_min_area_px && (best < 0 || g->n > ws->region[DARK][best].n))
                best = (int)k;
        }
        if (best < 0)
            break;
        tried[n_found++] = (unsigned)best;
        if (pupil_of(img, p, ws, &ws->region[DARK][best], &out->eyes[out->eye_count]))
            out->eye_count++;
    }
    if (out->eye_count == 2 && out->eyes[1].cx < out->eyes[0].cx) { /* left to right in the image */
        ex_eye t = out->eyes[0];
        out->eyes[0] = out->eyes[1];
        out->eyes[1] = t;
    }
    for (unsigned i = 0; i < out->eye_count; i++)
        match_glints(p, spots, n_spots, lit_mask, &out->eyes[i]);
    out->blink = out->eye_count == 0 && out->iris_px < p->blink_iris_px;
    if (out->blink)
        for (unsigned i = 0; i < EX_MAX_EYES; i++)
            out->eyes[i].flags = EX_PUPIL_BLINK;
    return 0;
}
