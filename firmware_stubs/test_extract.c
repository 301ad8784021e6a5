/*
 * test_extract.c - unit tests of the feature extractor (extract.c) on images drawn here with known answers:
 * conic fit and conversion, an anti-aliased pupil disc and ellipse, glints matched to the lit LEDs, blink,
 * edge cases (tiny, uniform, overflowing images, bad arguments). Exit status 0 if every check passes.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "extract.h"

#define W 160
#define H 120
#define SS 8 /* supersampling per axis for anti-aliased coverage */

static ex_workspace ws;
static uint8_t img[H][W];
static int failures;

#define CHECK(cond)                                                                                         \
    do {                                                                                                    \
        if (!(cond)) {                                                                                      \
            fprintf(stderr, "%s:%d: check failed: %s\n", __FILE__, __LINE__, #cond);                        \
            failures++;                                                                                     \
        }                                                                                                   \
    } while (0)

static int near(double a, double b, double tol)
{
    return fabs(a - b) <= tol;
}

/* Background `bg`, an ellipse (centre, semi-axes, angle deg) of level `in`, anti-aliased by supersampling. */
static void draw(double bg, double cx, double cy, double a, double b, double ang_deg, double in)
{
    double t = ang_deg * 3.14159265358979323846 / 180.0, c = cos(t), s = sin(t);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            int hits = 0;
            for (int i = 0; i < SS; i++)
                for (int j = 0; j < SS; j++) {
                    double px = x - 0.5 + (j + 0.5) / SS - cx, py = y - 0.5 + (i + 0.5) / SS - cy;
                    double u = px * c + py * s, v = -px * s + py * c;
                    hits += u * u / (a * a) + v * v / (b * b) <= 1.0;
                }
            img[y][x] = (uint8_t)lround(bg + (in - bg) * hits / (double)(SS * SS));
        }
}

/* A 2x2-pixel saturated plateau centred on (x + 0.5, y + 0.5) with a symmetric ring of 200. */
static void glint(int x, int y)
{
    for (int i = -1; i <= 2; i++)
        for (int j = -1; j <= 2; j++)
            img[y + i][x + j] = (i == -1 || i == 2 || j == -1 || j == 2) ? 200 : 255;
}

static ex_image image(void)
{
    ex_image im = {&img[0][0], W, H, W};
    return im;
}

static void test_conic(void)
{
    float x[40], y[40];
    double q[6], cx, cy, a, b, ang;
    for (int i = 0; i < 40; i++) { /* ellipse centre (30.25, -12.5), semi-axes 9 and 5, angle 30 deg */
        double t = 2.0 * 3.14159265358979323846 * i / 40, c = cos(0.5235987755982988), s = sin(0.5235987755982988);
        double u = 9.0 * cos(t), v = 5.0 * sin(t);
        x[i] = (float)(30.25 + u * c - v * s);
        y[i] = (float)(-12.5 + u * s + v * c);
    }
    CHECK(ex_fit_conic(x, y, NULL, 40, q) == 0);
    CHECK(ex_conic_to_ellipse(q, &cx, &cy, &a, &b, &ang) == 0);
    CHECK(near(cx, 30.25, 1e-4) && near(cy, -12.5, 1e-4));
    CHECK(near(a, 18.0, 1e-4) && near(b, 10.0, 1e-4) && near(ang, 30.0, 1e-3));
    {
        const double hyperbola[6] = {1, 0, -1, 0, 0, -1}, circle[6] = {1, 0, 1, -2, 0, -3}; /* (x-1)^2+y^2=4 */
        CHECK(ex_conic_to_ellipse(hyperbola, &cx, &cy, &a, &b, &ang) == -1);
        CHECK(ex_conic_to_ellipse(circle, &cx, &cy, &a, &b, &ang) == 0 && near(cx, 1, 1e-12) && near(a, 4, 1e-12));
    }
    CHECK(ex_fit_conic(x, y, NULL, 4, q) == -1); /* too few points */
}

static void test_pupil_disc_and_ellipse(void)
{
    ex_params p;
    ex_result r;
    ex_image im = image();
    ex_default_params(&p, 1);
    draw(95.0, 70.3, 55.7, 14.0, 14.0, 0.0, 25.0);
    CHECK(ex_extract(&im, &p, 0, 1, &ws, &r) == 0);
    CHECK(r.eye_count == 1 && !r.blink && r.flags == 0);
    CHECK(r.eyes[0].flags == EX_PUPIL_DETECTED && r.eyes[0].confidence > 0.8f);
    CHECK(near(r.eyes[0].cx, 70.3, 0.02) && near(r.eyes[0].cy, 55.7, 0.02));
    CHECK(near(r.eyes[0].axis_a, 28.0, 0.3) && near(r.eyes[0].axis_b, 28.0, 0.3));
    draw(95.0, 80.6, 60.2, 16.0, 11.0, 120.0, 25.0);
    CHECK(ex_extract(&im, &p, 0, 1, &ws, &r) == 0 && r.eye_count == 1);
    CHECK(near(r.eyes[0].cx, 80.6, 0.02) && near(r.eyes[0].cy, 60.2, 0.02));
    CHECK(near(r.eyes[0].axis_a, 32.0, 0.3) && near(r.eyes[0].axis_b, 22.0, 0.3) && near(r.eyes[0].angle_deg, 120.0, 0.5));
    CHECK(r.eyes[0].glint_count == 0);
}

static void test_glints_follow_the_lit_leds(void)
{
    ex_params p;
    ex_result r;
    ex_image im = image();
    ex_default_params(&p, 1); /* LED 0's glint is the one at larger x */
    draw(95.0, 70.0, 60.0, 12.0, 12.0, 0.0, 25.0);
    glint(90, 60); /* centre (90.5, 60.5), LED 0 */
    glint(50, 60); /* centre (50.5, 60.5), LED 1 */
    CHECK(ex_extract(&im, &p, 0x3, 1, &ws, &r) == 0 && r.eye_count == 1);
    CHECK(r.eyes[0].glint_count == 2 && r.eyes[0].glints[0].led == 0 && r.eyes[0].glints[1].led == 1);
    CHECK(r.eyes[0].glints[0].flags == (EX_GLINT_VALID | EX_GLINT_SATURATED));
    CHECK(near(r.eyes[0].glints[0].x, 90.5, 1e-4) && near(r.eyes[0].glints[0].y, 60.5, 1e-4));
    CHECK(near(r.eyes[0].glints[1].x, 50.5, 1e-4) && near(r.eyes[0].glints[1].y, 60.5, 1e-4));
    ex_default_params(&p, 0); /* the LEDs swapped on the board: so are the glints */
    CHECK(ex_extract(&im, &p, 0x3, 1, &ws, &r) == 0 && near(r.eyes[0].glints[0].x, 50.5, 1e-4));
    /* only LED 1 lit, and only its reflection in the image */
    draw(95.0, 70.0, 60.0, 12.0, 12.0, 0.0, 25.0);
    glint(50, 60);
    ex_default_params(&p, 1);
    CHECK(ex_extract(&im, &p, 0x2, 1, &ws, &r) == 0 && r.eyes[0].glint_count == 1);
    CHECK(r.eyes[0].glints[0].led == 1 && (r.eyes[0].glints[0].flags & EX_GLINT_VALID));
    /* two LEDs lit, one reflection: ambiguous, neither valid */
    CHECK(ex_extract(&im, &p, 0x3, 1, &ws, &r) == 0 && r.eyes[0].glint_count == 2);
    CHECK(r.eyes[0].glints[0].flags == EX_GLINT_AMBIGUOUS && r.eyes[0].glints[1].flags == EX_GLINT_AMBIGUOUS);
    /* a glint on the pupil's edge is flagged */
    draw(95.0, 70.0, 60.0, 12.0, 12.0, 0.0, 25.0);
    glint(81, 59);
    CHECK(ex_extract(&im, &p, 0x1, 1, &ws, &r) == 0 && (r.eyes[0].glints[0].flags & EX_GLINT_ON_PUPIL_EDGE));
}

static void test_two_eyes_left_to_right(void)
{
    ex_params p;
    ex_result r;
    ex_image im = image();
    ex_default_params(&p, 1);
    draw(95.0, 110.0, 60.0, 14.0, 14.0, 0.0, 25.0);
    for (int y = 40; y < 70; y++) /* a second, smaller pupil on the left */
        for (int x = 20; x < 50; x++)
            if ((x - 35) * (x - 35) + (y - 55) * (y - 55) <= 81)
                img[y][x] = 25;
    CHECK(ex_extract(&im, &p, 0, 2, &ws, &r) == 0 && r.eye_count == 2);
    CHECK(near(r.eyes[0].cx, 35.0, 0.3) && near(r.eyes[1].cx, 110.0, 0.05));
    CHECK(ex_extract(&im, &p, 0, 1, &ws, &r) == 0 && r.eye_count == 1 && near(r.eyes[0].cx, 110.0, 0.05));
}

static void test_blink_and_edge_cases(void)
{
    ex_params p;
    ex_result r;
    ex_image im = image();
    ex_default_params(&p, 1);
    memset(img, 185, sizeof img); /* lids shut: skin only */
    CHECK(ex_extract(&im, &p, 0x3, 1, &ws, &r) == 0 && r.eye_count == 0 && r.blink == 1);
    CHECK(r.eyes[0].flags == EX_PUPIL_BLINK);
    memset(img, 95, sizeof img); /* iris everywhere, no pupil: not a blink */
    CHECK(ex_extract(&im, &p, 0x3, 1, &ws, &r) == 0 && r.eye_count == 0 && r.blink == 0);
    memset(img, 0, sizeof img); /* all dark: one region filling the image, no edge to find */
    CHECK(ex_extract(&im, &p, 0x3, 2, &ws, &r) == 0 && r.dark_regions == 1);
    for (int y = 0; y < H; y++) /* a checkerboard of dark and bright pixels: more runs than the table */
        for (int x = 0; x < W; x++)
            img[y][x] = ((x + y) & 1) ? 255 : 0;
    CHECK(ex_extract(&im, &p, 0x3, 2, &ws, &r) == 0 && (r.flags & EX_OVERFLOW));
    im.width = 3; /* bad arguments */
    CHECK(ex_extract(&im, &p, 0x3, 1, &ws, &r) == -1 && r.eye_count == 0);
    im.width = W;
    im.stride = W - 1;
    CHECK(ex_extract(&im, &p, 0x3, 1, &ws, &r) == -1);
    im.stride = W;
    CHECK(ex_extract(&im, &p, 0x4, 1, &ws, &r) == -1);    /* a third LED */
    CHECK(ex_extract(&im, &p, 0x1, 3, &ws, &r) == -1);    /* three eyes */
    CHECK(ex_extract(NULL, &p, 0x1, 1, &ws, &r) == -1);
    im.width = 4;
    im.height = 4;
    memset(img, 25, sizeof img);
    CHECK(ex_extract(&im, &p, 0x1, 1, &ws, &r) == 0); /* tiny: no crash, whatever it finds */
}

int main(void)
{
    test_conic();
    test_pupil_disc_and_ellipse();
    test_glints_follow_the_lit_leds();
    test_two_eyes_left_to_right();
    test_blink_and_edge_cases();
    if (failures) {
        fprintf(stderr, "test_extract: %d check(s) failed\n", failures);
        return 1;
    }
    printf("test_extract: all checks passed\n");
    return 0;
}
