/* Projected Gauss-Seidel on the dense H: an external solver for contactbench.
 *
 * It follows the file protocol contactbench-qp/1 (docs/external-solvers.md) and
 * nothing else: it reads n, tol, time_limit and max_iter from problem.json with a tiny scanner,
 * the arrays ubar.f64 and H.f64 (and p0.f64 when present), and writes p.f64 and
 * solution.json into the solution directory.
 *
 *   cc -O2 -o pgs pgs.c -lm
 *   ./pgs PROBLEM_DIR SOLUTION_DIR            (exit 0: an answer was written)
 *   ./pgs --version                           (one line: the program and its version; exit 0)
 *
 * The stopping test is the harness's scaled KKT error (problems/kkt.py, problem_scales):
 *   u_s = max(max ubar, 1e-6 |ubar|_inf) (the approach; 1 when that is 0 or p_s would underflow),
 *   p_s = u_s / max diag H,
 *   err = max(max(0, -min w) / u_s, max_i |w_i p_i| / (u_s p_s)),  w = Hp - ubar
 * (p >= 0 by construction, so the primal figure is 0).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define PGS_VERSION "pgs 1.1"
/* problems/kkt.py: RELIEF_SHARE (the least share of |ubar|_inf in u_s) and U_SCALE_FALLBACK */
#define RELIEF_SHARE 1e-6
#define U_SCALE_FALLBACK 1.0

static char *slurp(const char *path, long *size) {
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    *size = ftell(f);
    fseek(f, 0, SEEK_SET);
    char *buf = malloc(*size + 1);
    if (fread(buf, 1, *size, f) != (size_t)*size) { fclose(f); free(buf); return NULL; }
    buf[*size] = 0;
    fclose(f);
    return buf;
}

/* The number after "key": in the JSON text (top-level scalars only; NAN when absent or null). */
static double json_number(const char *text, const char *key) {
    char pat[64];
    snprintf(pat, sizeof pat, "\"%s\"", key);
    const char *s = strstr(text, pat);
    if (!s) return NAN;
    s = strchr(s + strlen(pat), ':');
    if (!s) return NAN;
    char *end;
    double v = strtod(s + 1, &end);
    return end == s + 1 ? NAN : v;
}

static double *read_f64(const char *dir, const char *name, long count) {
    char path[4096];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    long size;
    char *buf = slurp(path, &size);
    if (!buf) return NULL;
    if (size != count * 8) { fprintf(stderr, "%s: %ld bytes, expected %ld\n", path, size, count * 8); exit(2); }
    return (double *)buf; /* little-endian hosts only, as the protocol's files are */
}

static double now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

int main(int argc, char **argv) {
    if (argc == 2 && strcmp(argv[1], "--version") == 0) { printf("%s\n", PGS_VERSION); return 0; }
    if (argc != 3) { fprintf(stderr, "usage: pgs PROBLEM_DIR SOLUTION_DIR | pgs --version\n"); return 2; }
    const char *pdir = argv[1], *sdir = argv[2];
    double t0 = now();
    char path[4096];
    long size;
    snprintf(path, sizeof path, "%s/problem.json", pdir);
    char *json = slurp(path, &size);
    if (!json) { fprintf(stderr, "cannot read %s\n", path); return 2; }
    long n = (long)json_number(json, "n");
    double tol = json_number(json, "tol"), limit = json_number(json, "time_limit");
    double limit_iter = json_number(json, "max_iter"); /* NAN when null: no limit of the harness's */
    if (!(tol > 0)) tol = 1e-8;
    free(json);
    double *ubar = read_f64(pdir, "ubar.f64", n), *H = read_f64(pdir, "H.f64", n * n);
    if (!ubar || !H) { fprintf(stderr, "pgs needs ubar.f64 and H.f64 (n = %ld)\n", n); return 2; }
    double *p = read_f64(pdir, "p0.f64", n);
    if (!p) p = calloc(n, sizeof(double));
    double *Hp = calloc(n, sizeof(double));
    for (long i = 0; i < n; i++) {
        if (p[i] < 0) p[i] = 0;
        for (long j = 0; j < n; j++) Hp[i] += H[i * n + j] * p[j];
    }
    double dmax = 0, umax = 0, utop = 0; /* max diag H, |ubar|_inf, max(max ubar, 0) */
    for (long i = 0; i < n; i++) {
        if (H[i * n + i] > dmax) dmax = H[i * n + i];
        if (fabs(ubar[i]) > umax) umax = fabs(ubar[i]);
        if (ubar[i] > utop) utop = ubar[i];
    }
    /* the judge's displacement scale: the approach, at least RELIEF_SHARE of the relief */
    double us = fmax(utop, RELIEF_SHARE * umax);
    if (!(us > 0 && us / dmax > 0)) us = U_SCALE_FALLBACK;
    double ps = us / dmax;
    long it = 0, max_iter = 1000000;
    if (limit_iter >= 0 && limit_iter < max_iter) max_iter = (long)limit_iter; /* honour the harness's limit */
    double err = INFINITY;
    const char *status = "max_iter";
    for (it = 1; it <= max_iter; it++) {
        /* one sweep; Hp (= H p) is kept up to date column by column (H is symmetric) */
        for (long i = 0; i < n; i++) {
            double pi = p[i] + (ubar[i] - Hp[i]) / H[i * n + i];
            if (pi < 0) pi = 0;
            double d = pi - p[i];
            if (d != 0) {
                const double *col = H + i * n;
                for (long j = 0; j < n; j++) Hp[j] += col[j] * d;
                p[i] = pi;
            }
        }
        if (it % 10 == 0 || n < 64) {
            for (long i = 0; i < n; i++) { /* refresh H p against drift */
                double s = 0;
                for (long j = 0; j < n; j++) s += H[i * n + j] * p[j];
                Hp[i] = s;
            }
            double dual = 0, comp = 0;
            for (long i = 0; i < n; i++) {
                double w = Hp[i] - ubar[i];
                if (-w > dual) dual = -w;
                if (fabs(w * p[i]) > comp) comp = fabs(w * p[i]);
            }
            err = fmax(dual / us, comp / (us * ps));
            if (err <= tol) { status = "converged"; break; }
            if (limit > 0 && now() - t0 > 0.9 * limit) { status = "time_limit"; break; }
        }
    }
    if (it > max_iter) it = max_iter;
    snprintf(path, sizeof path, "%s/p.f64", sdir);
    FILE *f = fopen(path, "wb");
    if (!f || fwrite(p, sizeof(double), n, f) != (size_t)n) { fprintf(stderr, "cannot write %s\n", path); return 3; }
    fclose(f);
    snprintf(path, sizeof path, "%s/solution.json", sdir);
    f = fopen(path, "w");
    fprintf(f, "{\"iterations\": %ld, \"status\": \"%s\", \"time_s\": %.6g}\n", it, status, now() - t0);
    fclose(f);
    printf("pgs: n = %ld, %ld sweeps, scaled KKT %.3g, %s\n", n, it, err, status);
    return 0;
}
