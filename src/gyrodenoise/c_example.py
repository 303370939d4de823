"""The C export's example program (example_main.c): a CSV stream through the stamped step `gd_step_t`, as an onboard
loop calls it: a refused sample is dropped (said on stderr) and the stream goes on; a gap restarts the stream.

`--unstamped` feeds the samples to `gd_step` instead, as consecutive, without looking at t (the stamps of a recording
in seconds, or none). Exit status: 0, or 1 when a sample was refused or a line could not be read, or when the gyro's
first samples are clearly in deg/s (the streaming corrector's range check, `StreamingCorrector._warn_gyro_range`: the
99th-percentile |gyro| over the first UNIT_PROBE samples above GYRO_P99_MAX rad/s; it warns, the example stops).
The output's header line starts with '#', as the project's other CSV outputs do (`correct`'s imu_corrected.csv).
"""

from __future__ import annotations

from gyrodenoise.c_clock import CODES
from gyrodenoise.data.checks import GYRO_P99_MAX
from gyrodenoise.streaming import UNIT_PROBE

UNSTAMPED = "--unstamped"
REFUSALS = {  # what stderr says of a refused sample
    "GD_REFUSED_SAMPLE": "a NaN/inf or a value beyond any IMU's range",
    "GD_REFUSED_ORDER": "its stamp is not after the previous sample's (repeated or late; stamps in whole seconds "
    "repeat like this: write them in nanoseconds)",
    "GD_REFUSED_EARLY": "it comes too long before its expected time (a stream faster than the model's rate, or stamps "
    "not in nanoseconds)",
    "GD_REFUSED_UNSTAMPED": "no stamp on a stamped stream",
}

EXAMPLE_CODE = """\
/* Correct a CSV stream with the exported model: lines t,gx,gy,gz,ax,ay,az (t integer nanoseconds, gyro rad/s, acc
   m/s^2) on stdin, lines t,wx,wy,wz (corrected gyro rad/s{std_cols_doc}) on stdout, t copied as written. Empty
   lines and lines that start with a letter or # (a header, comments) are skipped; any other line must be 7 numbers.
   A header before the first sample whose names put the accelerometer where the gyro is read (or the reverse) stops
   the run: the columns are read by position.

   Each sample goes through gd_step_t with its stamp, as an onboard loop would: a refused sample (a NaN, a stamp not
   after the previous one or too soon after it) is dropped, with a line on stderr and no output line; after a gap the
   stream restarts (said on stderr). With {unstamped}, t is not read: the samples are taken as consecutive (gd_step).
   Exit status: 0, or 1 when a sample was refused (said with its line number) or a line was not t,gx,gy,gz,ax,ay,az
   (the run stops there, and says how many samples before it were read), or when the gyro is clearly in deg/s: the
   99th-percentile |gyro| over the first UNIT_PROBE samples taken above GYRO_P99_MAX rad/s, a rate no motion keeps up
   (gyrodenoise's streaming corrector warns on the same rule; the run stops at the line of the last of them).

   Compile: {compile}
   Run:     ./gyrodenoise < imu.csv > corrected.csv
*/
#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gyrodenoise_model.h"

static gd_state state; /* static: zeroed (a reset state), and off the stack (sizeof(gd_state) may be large) */

#define UNIT_PROBE {unit_probe}         /* samples taken before the gyro's unit is judged, once */
#define GYRO_P99_MAX {gyro_p99_max} /* rad/s: a 99th-percentile |gyro| above it is a gyro in deg/s */
static double probe[UNIT_PROBE]; /* |gyro| of the first samples taken */

static int ascending(const void *a, const void *b)
{{
    const double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}}

/* the q-th percentile of v[0..n-1] (sorted in place), linear between the order statistics as numpy's default */
static double percentile(double *v, int n, double q)
{{
    qsort(v, (size_t)n, sizeof *v, ascending);
    const double pos = q / 100.0 * (n - 1);
    const int lo = (int)pos, hi = lo + 1 < n ? lo + 1 : lo;
    return v[lo] + (pos - lo) * (v[hi] - v[lo]);
}}

static const char *refusal(int code)
{{
    switch (code) {{
{refusals}
    }}
    return "refused";
}}

/* a line that ends the run: what was wrong, and that the lines after it were not read */
static int stop(long lineno, long n, const char *why)
{{
    fprintf(stderr, "line %ld: %s; stopped there: the lines after it were not read (the %ld samples before it were: "
                    "their outputs, or the refusals said above)\\n", lineno, why, n);
    return 1;
}}

/* a header's column names against the order read (t, gyro x y z, acc x y z): the column number (from 1) of the first
   name that says the other sensor (acc where a gyro is read, gyro where an acc is read), or 0 */
static int header_mismatch(const char *line, char *name, size_t size)
{{
    char buf[1024];
    int col = 0;
    snprintf(buf, sizeof buf, "%s", line);
    for (char *f = strtok(buf, ",\\r\\n"); f; f = strtok(NULL, ",\\r\\n"), col++) {{
        for (char *c = f; *c; c++) *c = (char)tolower((unsigned char)*c);
        const int gyro = strstr(f, "gyr") || strstr(f, "omega") || strstr(f, "ang_vel") || strstr(f, "rad/s") ||
                         strstr(f, "deg/s") || strstr(f, "dps");
        const int acc = strstr(f, "acc") || strstr(f, "m/s^2") || strstr(f, "m s^-2");
        if ((col >= 1 && col <= 3 && acc && !gyro) || (col >= 4 && col <= 6 && gyro && !acc)) {{
            snprintf(name, size, "%s", f + strspn(f, " \\t#"));
            return col + 1;
        }}
    }}
    return 0;
}}

/* t as int64 ns: digits only (a sign allowed), spaces after them */
static int read_stamp(const char *t, int64_t *t_ns)
{{
    char *end;
    errno = 0;
    const long long v = strtoll(t, &end, 10);
    if (end == t || errno) return 0;
    end += strspn(end, " \\t");
    *t_ns = (int64_t)v;
    return *end == '\\0';
}}

int main(int argc, char **argv)
{{
    const int stamped = argc == 1;
    if (argc > 2 || (argc == 2 && strcmp(argv[1], "{unstamped}") != 0)) {{
        fprintf(stderr, "usage: %s [{unstamped}] < imu.csv > corrected.csv\\n", argv[0]);
        return 2;
    }}
    char line[1024];
    long n = 0, lineno = 0, refused = 0, taken = 0;
    printf("#t,wx [rad s^-1],wy [rad s^-1],wz [rad s^-1]{std_cols}\\n");
    while (fgets(line, sizeof line, stdin)) {{
        lineno++;
        if (!strchr(line, '\\n') && !feof(stdin))
            return stop(lineno, n, "longer than 1022 characters: not t,gx,gy,gz,ax,ay,az");
        char *p = line + strspn(line, " \\t\\r\\n"), *end;
        if (*p == '\\0' || *p == '#' || isalpha((unsigned char)*p)) {{ /* empty, a comment, a header */
            char name[256], why[400];
            const int col = n == 0 ? header_mismatch(p, name, sizeof name) : 0;
            if (col) {{
                snprintf(why, sizeof why, "the header names column %d '%.200s' where %s %c is read: write the "
                         "columns as t,gx,gy,gz,ax,ay,az (they are read by position)", col, name,
                         col <= 4 ? "gyro" : "acc", "xyz"[(col - 2) % 3]);
                return stop(lineno, n, why);
            }}
            continue;
        }}
        const char *t = p;
        float imu[6], w[3], sd[3];
        int64_t t_ns = 0;
        for (int c = 0; c < 6; c++) {{
            p = strchr(p, ',');
            if (p) *p++ = '\\0'; /* ends t (c == 0), then steps over each comma */
            imu[c] = p ? strtof(p, &end) : 0.0f;
            if (!p || end == p) return stop(lineno, n, "expected t,gx,gy,gz,ax,ay,az");
            p = end;
        }}
        if (p[strspn(p, " \\t\\r\\n")] != '\\0')
            return stop(lineno, n, "more than 7 columns: expected t,gx,gy,gz,ax,ay,az");
        if (stamped && !read_stamp(t, &t_ns)) {{
            char why[300];
            snprintf(why, sizeof why, "t=%.40s is not integer nanoseconds: write t as int64 ns (seconds x 1e9), or "
                     "run with {unstamped} to take the samples as consecutive, unchecked", t);
            return stop(lineno, n, why);
        }}
        n++;
        const int code = stamped ? gd_step_t(&state, t_ns, imu, w, sd) : gd_step(&state, imu, w, sd);
        if (code < 0) {{
            fprintf(stderr, "line %ld (sample %ld, t=%s): %s: dropped\\n", lineno, n, t, refusal(code));
            refused++;
            continue;
        }}
        if (taken < UNIT_PROBE) {{
            const double gx = (double)imu[0], gy = (double)imu[1], gz = (double)imu[2];
            probe[taken++] = sqrt(gx * gx + gy * gy + gz * gz);
            const double p99 = taken == UNIT_PROBE ? percentile(probe, UNIT_PROBE, 99.0) : 0.0;
            if (p99 > GYRO_P99_MAX) {{
                fprintf(stderr, "line %ld (sample %ld, t=%s): the gyro's 99th-percentile norm over the first %d "
                                "samples is %.3g rad/s (%.0f deg/s); real motion stays below ~%g rad/s: it looks like "
                                "deg/s. The model needs rad/s: multiply the gyro by pi/180 (0.0174533); stopped there: "
                                "the lines after it were not read, and the %ld output lines before it are wrong\\n",
                        lineno, n, t, UNIT_PROBE, p99, p99 * 57.29577951308232, GYRO_P99_MAX, taken - 1);
                return 1;
            }}
        }}
        if (code == GD_RESTARTED)
            fprintf(stderr, "line %ld (sample %ld, t=%s): a gap before it, or the clock went back: the stream "
                            "restarted (the next %d outputs are less accurate)\\n", lineno, n, t, GD_RECEPTIVE_FIELD);
        if (code == GD_RATE_OFF)
            fprintf(stderr, "line %ld (sample %ld, t=%s): the stream's rate is more than %g %% off the model's %g "
                            "Hz: resample it, or use a model trained at its rate\\n", lineno, n, t,
                    100.0 * (double)GD_RATE_TOL, (double)GD_RATE_HZ);
        printf("%s,%.9g,%.9g,%.9g", t, (double)w[0], (double)w[1], (double)w[2]);
{std_print}        printf("\\n");
    }}
    if (refused) fprintf(stderr, "%ld of %ld samples refused (no output line for them)\\n", refused, n);
    return refused ? 1 : 0;
}}
"""


def example_source(ensemble: bool, compile_command: str) -> str:
    """example_main.c's text; an ensemble's output has the members' spread too."""
    std_print = '        printf(",%.9g,%.9g,%.9g", (double)sd[0], (double)sd[1], (double)sd[2]);\n' if ensemble else ""
    refusals = "\n".join(f'    case {name}: return "{REFUSALS[name]}";' for name, value, _ in CODES if value < 0)
    return EXAMPLE_CODE.format(
        compile=compile_command,
        unstamped=UNSTAMPED,
        unit_probe=UNIT_PROBE,
        gyro_p99_max=f"{float(GYRO_P99_MAX)!r}",
        refusals=refusals,
        std_cols=",w_std_x [rad s^-1],w_std_y [rad s^-1],w_std_z [rad s^-1]" if ensemble else "",
        std_cols_doc=", then the members' spread w_std_x,w_std_y,w_std_z" if ensemble else "",
        std_print=std_print,
    )
