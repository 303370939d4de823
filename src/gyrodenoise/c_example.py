"""The C export's example program (example_main.c): a CSV stream through the stamped step `gd_step_t`, as an onboard
loop calls it: a refused sample is dropped (said on stderr) and the stream goes on; a gap restarts the stream.

`--unstamped` feeds the samples to `gd_step` instead, as consecutive, without looking at t (the stamps of a recording
in seconds, or none). Exit status: 0, or 1 when a sample was refused or a line could not be read.
"""

from __future__ import annotations

from gyrodenoise.c_clock import CODES

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

   Each sample goes through gd_step_t with its stamp, as an onboard loop would: a refused sample (a NaN, a stamp not
   after the previous one or too soon after it) is dropped, with a line on stderr and no output line; after a gap the
   stream restarts (said on stderr). With {unstamped}, t is not read: the samples are taken as consecutive (gd_step).
   Exit status: 0, or 1 when a sample was refused or a line was not t,gx,gy,gz,ax,ay,az.

   Compile: {compile}
   Run:     ./gyrodenoise < imu.csv > corrected.csv
*/
#include <ctype.h>
#include <errno.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gyrodenoise_model.h"

static gd_state state; /* static: zeroed (a reset state), and off the stack (sizeof(gd_state) may be large) */

static const char *refusal(int code)
{{
    switch (code) {{
{refusals}
    }}
    return "refused";
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
    long n = 0, lineno = 0, refused = 0;
    printf("t,wx,wy,wz{std_cols}\\n");
    while (fgets(line, sizeof line, stdin)) {{
        lineno++;
        if (!strchr(line, '\\n') && !feof(stdin)) {{
            fprintf(stderr, "line %ld: longer than %d characters: not t,gx,gy,gz,ax,ay,az\\n", lineno,
                    (int)sizeof line - 2);
            return 1;
        }}
        char *p = line + strspn(line, " \\t\\r\\n"), *end;
        if (*p == '\\0' || *p == '#' || isalpha((unsigned char)*p)) continue; /* empty, a comment, a header */
        const char *t = p;
        float imu[6], w[3], sd[3];
        int64_t t_ns = 0;
        for (int c = 0; c < 6; c++) {{
            p = strchr(p, ',');
            if (p) *p++ = '\\0'; /* ends t (c == 0), then steps over each comma */
            imu[c] = p ? strtof(p, &end) : 0.0f;
            if (!p || end == p) {{
                fprintf(stderr, "line %ld: expected t,gx,gy,gz,ax,ay,az\\n", lineno);
                return 1;
            }}
            p = end;
        }}
        if (p[strspn(p, " \\t\\r\\n")] != '\\0') {{
            fprintf(stderr, "line %ld: more than 7 columns: expected t,gx,gy,gz,ax,ay,az\\n", lineno);
            return 1;
        }}
        if (stamped && !read_stamp(t, &t_ns)) {{
            fprintf(stderr, "line %ld: t=%s is not integer nanoseconds: write t as int64 ns (seconds x 1e9), or "
                            "run with {unstamped} to take the samples as consecutive, unchecked\\n", lineno, t);
            return 1;
        }}
        n++;
        const int code = stamped ? gd_step_t(&state, t_ns, imu, w, sd) : gd_step(&state, imu, w, sd);
        if (code < 0) {{
            fprintf(stderr, "sample %ld (t=%s): %s: dropped\\n", n, t, refusal(code));
            refused++;
            continue;
        }}
        if (code == GD_RESTARTED)
            fprintf(stderr, "sample %ld (t=%s): a gap before it, or the clock went back: the stream restarted (the "
                            "next %d outputs are less accurate)\\n", n, t, GD_RECEPTIVE_FIELD);
        if (code == GD_RATE_OFF)
            fprintf(stderr, "sample %ld (t=%s): the stream's rate is more than %g %% off the model's %g Hz: "
                            "resample it, or use a model trained at its rate\\n", n, t, 100.0 * (double)GD_RATE_TOL,
                    (double)GD_RATE_HZ);
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
        refusals=refusals,
        std_cols=",w_std_x,w_std_y,w_std_z" if ensemble else "",
        std_cols_doc=", then the members' spread w_std_x,w_std_y,w_std_z" if ensemble else "",
        std_print=std_print,
    )
