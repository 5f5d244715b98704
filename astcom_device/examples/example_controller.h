/* The example controller: the Python example device's variables and functions, plus a
 * minimal two-axis trajectory follower with the roles of a VSS mapping file
 * (astcom_device/examples/follower-mapping.json). Portable: no OS calls; the host gives
 * the wall clock (for PPS edges) through ex_init. */
#ifndef EXAMPLE_CONTROLLER_H
#define EXAMPLE_CONTROLLER_H

#include <stddef.h>
#include <stdint.h>

#include "astcom_device.h"

#ifndef EX_TRAJ_CAPACITY
#define EX_TRAJ_CAPACITY 4096   /* trajectory points (the MCU build uses fewer) */
#endif
#define EX_MAX_EXTRA 16         /* extra.sNN traced sines, for load */

/* Mount states, as the mapping's state_codes */
enum { EX_OFF = 0, EX_HOLDING = 1, EX_SLEWING = 2, EX_TRACKING = 3, EX_MANUAL = 4,
       EX_STOPPING = 5, EX_FAULT = 6 };

typedef int64_t (*ex_clock_fn)(void);

/* Set the state up; `start_t_us` is the mount time of tick 0; `wall_us` (may be NULL)
 * is the host's UTC clock, whose whole seconds are the PPS edges of time.set_utc. */
void ex_init(double loop_rate_hz, int64_t start_t_us, ex_clock_fn wall_us);
/* The tables: `n_extra` extra traced sines are appended (0..EX_MAX_EXTRA). */
const ad_var *ex_vars(unsigned n_extra, size_t *n);
const ad_fn *ex_fns(size_t *n);
/* Compute tick `tick`; returns its mount time (µs). Call with the critical section held. */
int64_t ex_step(uint64_t tick);

#endif
