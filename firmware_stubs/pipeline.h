/*
 * pipeline.h - the firmware's image pipeline (HAL_SOURCE_PIXELS): one raw frame -> the FEATURES record of
 * the selected eyes, by the extractor (extract.h) and an eye assignment that remembers where each eye was.
 *
 * Eye assignment: with one eye selected, the largest pupil is that eye; with both, two pupils are ordered
 * by image x (hal_camera_info.right_eye_low_x), and a lone pupil goes to the eye last seen nearer to it
 * (without a memory: to the side of the window's centre it lies on). Pupil flags: DETECTED, PARTIAL (part
 * of the edge hidden: eyelid, window border; PARTIAL alone: so much that the pupil is tracked but not
 * reported, its ellipse fields 0), BLINK (no pupil and the eye looks closed). One glint record
 * per LED lit in the frame, in LED order. Coordinates: full-sensor px (the window's origin added).
 */
#define PL_MARGIN_X 160u
#define PL_MARGIN_Y 120u
#define PL_MIN_W 320u
#define PL_MIN_H 240u
#define PL_LOST_FRAMES 10u
#ifndef EH_PIPELINE_H
#define EH_PIPELINE_H

#include "hal.h"

/* The camera the frames come from (LED layout, eye order); call once, and pl_reset at each START. */
void pl_init(const hal_camera_info *cam);

/* Forget where the eyes were. */
void pl_reset(void);

/* Fill the eye records of `out` (frame_id and timestamp too) from `frame` for the eyes selected by `eyes`
 * (bit 0 right, bit 1 left). Returns 0; -1 if the frame is unusable (the record then says nothing found). */
int pl_features(const hal_frame *frame, uint8_t eyes, hal_exposure *out);

/* The tracking window for the next frames (the host asked for the full sensor): the box of the selected eyes'
 * last pupil centres widened by PL_MARGIN_X/Y px, at least PL_MIN_W x PL_MIN_H, on the sensor; the full
 * sensor until every selected eye has been found, and again once one has been lost (not found, not blinking)
 * for PL_LOST_FRAMES frames. Fills win (x, y, w, h). */
void pl_window(uint8_t eyes, uint16_t win[4]);

#endif
