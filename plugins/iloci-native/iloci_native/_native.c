/*
 * native-rnnpb's float32 kernel in C: every epoch of
 * iloci_native.rnnpb.NativeRNNPB.train (closed-loop forward pass, hand-written
 * BPTT, gradient clipping, the learning-rate schedule, Adam on the weights
 * and on the PBs) in one call, and every Levenberg-Marquardt step of its
 * recognition (forward-mode derivatives along the PB) in another, for one of
 * three instruction sets chosen at run time: AVX-512, AVX2 + FMA, or
 * portable C.
 *
 * Why: at paper size a training step is ~200 matrix products of 36 x 32 x 64.
 * Through torch each costs more to dispatch than to compute; here they are
 * register-blocked vector loops, and the whole training runs without
 * returning to Python. The algorithm and the update order are those of the
 * numpy reference (iloci.rnnpb.reference) and of torch-rnnpb (same formulas,
 * float32 arithmetic, its own rounding, the same on every CPU: below); tests
 * compare them step by step.
 *
 * The kernel is written once (_native_kernel.h, over a vector width) and
 * included here once per instruction set. The module is compiled without
 * -march flags: only the functions marked with a target attribute use
 * AVX2 or AVX-512, and iloci_rnnpb_isa_supported() asks the CPU at run time,
 * so a build never executes an instruction the machine lacks. The portable
 * path uses the platform's baseline vector unit (SSE2 on x86-64, NEON on
 * aarch64) and builds wherever GCC or Clang does.
 *
 * The float32 arithmetic, one definition for every instruction set (so one
 * seed trains bit-identical networks on any CPU; tests/plugins force each
 * path and compare, and an aarch64 build under qemu-user). The training's
 * is also written in numpy, iloci/rnnpb/float32.py (the reference's float32
 * mode), and tested bit for bit against every path:
 *
 *   - a matrix product's element C[i, j] = init + sum_k A[i, k] B[k, j] is
 *     acc = init (a bias, the row being added to, or +0), then for k
 *     ascending acc = fma(A[i, k], B[k, j], acc): one rounding per step;
 *     a vector holds independent j, so the width never changes a sum;
 *   - weight gradients sum over steps and rows in ascending order, the same
 *     way (fma per term); column sums add in ascending order (no products);
 *   - the dot products of the PB gradient: fmaf per term, ascending;
 *   - tanh: clamp to +-7.90531, x2 = x x, Horner with fma for the [13/6]
 *     rational p(x2), q(x2), then (x p) / q, a correctly rounded division
 *     (vtanh, stanh in _native_kernel.h; no reciprocal estimates);
 *   - d tanh: y (1 - e^2) as y * fma(-e, e, 1);
 *   - everything else (the loss, the mixing of inputs, Adam) separately
 *     rounded IEEE float32 operations in the source's order: compiled with
 *     -ffp-contract=off (pyproject.toml), so the compiler fuses nothing;
 *   - in float64: the clipping norm (8 partial sums in a fixed tree), Adam's
 *     step size (bias corrections as running products 0.9^t, 0.999^t), the
 *     decay factor decay^((t-1)/epochs) (libm pow: the one library call;
 *     glibc's is the same code on x86-64 and aarch64) and recognition's
 *     P x P systems (Cholesky in a fixed order).
 *
 * Layout: weights are padded inside to S_p = roundup16(D + C) state and
 * H_p = roundup16(H) hidden columns (whole vector registers at every width).
 * Padded units stay exactly zero: their weights start at zero, their
 * pre-activations are zero, tanh(0) = 0, and their gradients (hence Adam
 * updates) are zero.
 */
#ifndef ILOCI_NATIVE_NO_PYTHON  /* defined to build the kernel alone, e.g. to cross-compile */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#endif

#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define ILOCI_X86 1
#include <immintrin.h>  /* the SSE2 baseline's min/max, AVX2's and AVX-512's intrinsics */
#else
#define ILOCI_X86 0
#endif

/* Instruction sets, as iloci_rnnpb_train_args.isa and in rnnpb.py. */
enum { ISA_AUTO = 0, ISA_PORTABLE = 1, ISA_AVX2 = 2, ISA_AVX512 = 3 };

/* Return codes of iloci_rnnpb_train. */
enum { OK = 0, NO_MEMORY = 1, TOO_WIDE = 2, ISA_UNSUPPORTED = 3, BAD_ARGS = 4 };

/* Largest padded widths (H <= 256, D + C <= 256): tiles are sized for the
 * paper's 32 and 64 columns; wider layers still run, column block by block. */
#define WIDTH_MAX 256

/* The arguments of one training, mirrored by _TrainArgs in rnnpb.py (a
 * ctypes.Structure: named fields, so two swapped arguments cannot run).
 * Arrays are C-contiguous float32: X (T, R, D) padded sequences; mw (T - 1,
 * R) mask times each row's loss weight; w_in (D + C + P, H), b_hidden (H),
 * w_out (H, D + C), b_out (D + C), u (R, P) with PB = bound tanh(u): all
 * updated in place. loss_history, when not NULL, receives the loss of each
 * epoch (before its update). */
typedef struct {
    int32_t size;               /* sizeof(iloci_rnnpb_train_args): the caller's layout */
    int32_t isa;                /* ISA_*; ISA_AUTO: the best the CPU has */
    int32_t epochs, T, R, D, C, H, P;
    int32_t warmup;             /* epochs over which the weights' rate ramps up */
    float alpha;                /* closed_loop */
    float bound;                /* pb_bound */
    double lr, pb_lr;           /* learning rates: weights, PBs */
    double decay;               /* both rates decay to this fraction over `epochs` */
    double clip;                /* global norm of the weight gradient */
    const float *X, *mw;
    float *w_in, *b_hidden, *w_out, *b_out, *u;
    float *loss_history;        /* (epochs,) or NULL */
    /* out */
    float loss;                 /* loss of the last epoch run */
    int32_t epochs_run;
    int32_t isa_used;
} iloci_rnnpb_train_args;

static int round16(int n) { return (n + 15) / 16 * 16; }

/* n floats, zeroed, at a 64-byte boundary (free with free()): every padded
 * row then starts on a cache line, and no vector load or store straddles
 * two (calloc's blocks of this size start 16 bytes past a page: half the
 * AVX2 loads, every AVX-512 one, straddled). NULL when out of memory. */
static float *zeroed_floats(size_t n) {
    size_t bytes = (n * sizeof(float) + 63) / 64 * 64;
    void *p = NULL;
    if (posix_memalign(&p, 64, bytes ? bytes : 64) != 0) return NULL;
    memset(p, 0, bytes);
    return (float *)p;
}

/* The weights padded into the kernel's layout, flat = Ws (S_p, H_p) | Wp (P,
 * H_p) | bh (H_p) | Wo (H_p, S_p) | bo (S_p), zero-filled beforehand; and
 * s0 (R, S_p) = [x_0, 0] per row. The layout of both training and
 * recognition. */
static void pad_network(int D, int C, int H, int P, int R, const float *w_in,
                        const float *b_hidden, const float *w_out, const float *b_out,
                        const float *X, float *flat, float *s0) {
    const int S = D + C, Sp = round16(S), Hp = round16(H);
    float *Ws = flat, *Wp = Ws + (size_t)Sp * Hp, *bh = Wp + (size_t)P * Hp;
    float *Wo = bh + Hp, *bo = Wo + (size_t)Hp * Sp;
    for (int j = 0; j < S; j++) {
        for (int h = 0; h < H; h++) Ws[j * Hp + h] = w_in[j * H + h];
        bo[j] = b_out[j];
    }
    for (int k = 0; k < P; k++)
        for (int h = 0; h < H; h++) Wp[k * Hp + h] = w_in[(S + k) * H + h];
    for (int h = 0; h < H; h++) {
        bh[h] = b_hidden[h];
        for (int j = 0; j < S; j++) Wo[h * Sp + j] = w_out[h * S + j];
    }
    for (int r = 0; r < R; r++)
        for (int j = 0; j < D; j++) s0[r * Sp + j] = X[r * D + j];
}

/* The learning rates' decay factor at epoch t (1-based): decay^((t-1)/epochs). */
static double schedule_decay(const iloci_rnnpb_train_args *a, int t) {
    return pow(a->decay, (double)(t - 1) / a->epochs);
}

enum { EPI_NONE = 0, EPI_TANH = 1, EPI_DTANH = 2 };

/* The arguments of one recognition (mirrored by RecognizeArgs in native.py):
 * Levenberg-Marquardt on each row's PB, the weights frozen, exactly the
 * steps of torch-rnnpb's (TorchRNNPB._recognize_kernel): X (T, R, D) padded
 * sequences; sw (T - 1, R) the square root of mask times each row's weight;
 * the weights as in iloci_rnnpb_train_args (read only); u (R, P) the starts,
 * PB = bound tanh(u), updated in place; err (R,), when not NULL, receives
 * each row's final sum of squared weighted residuals. The LM constants are
 * iloci.rnnpb.common's LM_*. */
typedef struct {
    int32_t size;               /* sizeof(iloci_rnnpb_recognize_args) */
    int32_t isa;
    int32_t steps, T, R, D, C, H, P;
    float bound;
    double damping;             /* initial damping (recognition_damping) */
    double down, up, lam_min, lam_max, tiny, u_max;
    const float *X, *sw;
    const float *w_in, *b_hidden, *w_out, *b_out;
    float *u;
    float *err;
    int32_t isa_used;
} iloci_rnnpb_recognize_args;

/* PB units a recognition handles (its per-row systems live on the stack). */
#define LM_P_MAX 16

/* Padded weights and buffers of one recognition. */
typedef struct {
    int D, P, R, L, Sp, Hp;
    float bound;
    const float *X, *sw;
    float *Ws, *Wp, *bh, *Wo, *bo;    /* padded as in training */
    float *s0, *pre, *Hs, *Os, *dpre, *dh, *dout, *trial;
    double *sys;                      /* e, A, g of the current and the trial u; damping */
    float *mem;
} lm_work;

static void lm_work_free(lm_work *w) { free(w->mem); free(w->sys); }

/* Returns 0, or 1 when out of memory. */
static int lm_work_init(lm_work *w, const iloci_rnnpb_recognize_args *a) {
    const int D = a->D, H = a->H, P = a->P, R = a->R, S = a->D + a->C;
    const int Sp = round16(S), Hp = round16(H), L = a->T - 1;
    const size_t nWs = (size_t)Sp * Hp, nWp = (size_t)P * Hp, nWo = (size_t)Hp * Sp;
    size_t total = nWs + nWp + Hp + nWo + Sp + (size_t)R * Sp + (size_t)R * Hp
                   + (size_t)L * R * (Hp + Sp) + (size_t)P * R * (2 * Hp + Sp) + (size_t)R * P;
    w->mem = zeroed_floats(total);
    w->sys = (double *)calloc((size_t)R * (2 * (1 + P + P * P) + 1), sizeof(double));
    if (!w->mem || !w->sys) { lm_work_free(w); return 1; }
    w->D = D; w->P = P; w->R = R; w->L = L; w->Sp = Sp; w->Hp = Hp;
    w->bound = a->bound; w->X = a->X; w->sw = a->sw;
    w->Ws = w->mem; w->Wp = w->Ws + nWs; w->bh = w->Wp + nWp; w->Wo = w->bh + Hp;
    w->bo = w->Wo + nWo; w->s0 = w->bo + Sp; w->pre = w->s0 + (size_t)R * Sp;
    w->Hs = w->pre + (size_t)R * Hp; w->Os = w->Hs + (size_t)L * R * Hp;
    w->dpre = w->Os + (size_t)L * R * Sp; w->dh = w->dpre + (size_t)P * R * Hp;
    w->dout = w->dh + (size_t)P * R * Hp; w->trial = w->dout + (size_t)P * R * Sp;
    pad_network(D, a->C, H, P, R, a->w_in, a->b_hidden, a->w_out, a->b_out, a->X, w->Ws,
                w->s0);
    return 0;
}

/* Solves M x = b for a symmetric positive definite n x n M (Cholesky, in
 * place). Returns 0 where M is not positive definite or a value is not
 * finite (the step is then rejected, as torch's solve_ex's non-finite one). */
static int solve_spd(int n, double M[LM_P_MAX][LM_P_MAX], const double *b, double *x) {
    for (int j = 0; j < n; j++) {
        double d = M[j][j];
        for (int k = 0; k < j; k++) d -= M[j][k] * M[j][k];
        if (!(d > 0.0) || !isfinite(d)) return 0;
        M[j][j] = sqrt(d);
        for (int i = j + 1; i < n; i++) {
            double v = M[i][j];
            for (int k = 0; k < j; k++) v -= M[i][k] * M[j][k];
            M[i][j] = v / M[j][j];
        }
    }
    for (int i = 0; i < n; i++) {
        double v = b[i];
        for (int k = 0; k < i; k++) v -= M[i][k] * x[k];
        x[i] = v / M[i][i];
    }
    for (int i = n - 1; i >= 0; i--) {
        double v = x[i];
        for (int k = i + 1; k < n; k++) v -= M[k][i] * x[k];
        x[i] = v / M[i][i];
    }
    for (int i = 0; i < n; i++)
        if (!isfinite(x[i])) return 0;
    return 1;
}

/* Each instruction set below sets the kernel's register tiles: GEMM_NB_ROWS
 * (vectors, rows) of the forward and backward products' main column block,
 * TN_NB_ROWS (vectors, rows of W) of the weight gradients'. They keep
 * (vectors x rows) accumulators plus a row of B in the vector registers (16
 * for SSE2 and AVX2, 32 for AVX-512 and NEON); chosen by timing the
 * paper-size step on an AVX-512 machine (benchmarks/rnnpb.py; the portable
 * path's 4 x 3 forced on it: 4 % faster than 4 x 2 with SSE2). TN_CHUNK:
 * rows of the weight gradients' sums per pass (32 for SSE2 and AVX2: a step
 * 8 to 9 % faster than one pass over all rows, 24 to 96 about alike; none
 * for AVX-512, whose larger tiles were 1 to 1.5 % slower with chunks). */

#if defined(__clang__)
#pragma STDC FP_CONTRACT OFF
#elif defined(__GNUC__) && !defined(ILOCI_FP_CONTRACT_OFF)
/* GCC ignores the pragma, and nothing tells whether -ffp-contract=off is in
 * effect: the build passes -DILOCI_FP_CONTRACT_OFF with it. Without the
 * flag GCC would fuse products and sums where the instruction set has FMA,
 * and each path would round differently. */
#error "compile _native.c with -ffp-contract=off -DILOCI_FP_CONTRACT_OFF"
#endif

/* Lane by lane fmaf: the portable path where the vector unit has no fused
 * multiply-add (x86-64 before FMA3; slow, a libm call per lane, but the
 * same bits). */
#define VFMA_LANES(SUF, VT, N) \
    static inline __attribute__((always_inline)) VT vfma_lanes_##SUF(VT a, VT b, VT c) { \
        VT r; \
        for (int i = 0; i < (N); i++) r[i] = __builtin_fmaf(a[i], b[i], c[i]); \
        return r; \
    }
typedef float vf4_lanes __attribute__((vector_size(16)));
VFMA_LANES(portable, vf4_lanes, 4)

/* -- portable: the compiler's baseline vector unit ------------------------- */
#define VW 4
#define SUFFIX portable
#define K_UNROLL
#define GEMM_NB_ROWS 4, 3
#define TN_NB_ROWS 4, 2
#define TN_CHUNK 32
#define TARGET
#define WIDE 0
#if defined(__SSE2__)
#define VMIN _mm_min_ps
#define VMAX _mm_max_ps
#define SET1 _mm_set1_ps
#define VFMA(a, b, c) vfma_lanes_portable(a, b, c)
#elif defined(__ARM_NEON) && defined(__aarch64__)
#include <arm_neon.h>
#define VMIN vminq_f32
#define VMAX vmaxq_f32
#define SET1 vdupq_n_f32
#define VFMA(a, b, c) vfmaq_f32(c, a, b)  /* c + a b, one rounding (AArch64) */
#else
#define VFMA(a, b, c) vfma_lanes_portable(a, b, c)
#endif
#include "_native_kernel.h"  /* undefines the parameters above */

#if ILOCI_X86
/* -- portable on x86-64 with FMA3: the portable path's source, 4 floats, the
 * fused multiply-adds in one instruction (what ISA_PORTABLE runs on a CPU
 * with FMA; the same bits as the lane-by-lane fmaf above) ---------------- */
#define VW 4
#define SUFFIX portable_fma
#define K_UNROLL
#define GEMM_NB_ROWS 4, 3
#define TN_NB_ROWS 4, 2
#define TN_CHUNK 32
#define TARGET __attribute__((target("fma")))
#define WIDE 0
#define VMIN _mm_min_ps
#define VMAX _mm_max_ps
#define SET1 _mm_set1_ps
#define VFMA(a, b, c) _mm_fmadd_ps(a, b, c)
#include "_native_kernel.h"  /* undefines the parameters above */

/* -- AVX2 + FMA: 8 floats, 16 registers ------------------------------------ */
#define VW 8
#define SUFFIX avx2
#define K_UNROLL
#define GEMM_NB_ROWS 4, 3
#define TN_NB_ROWS 2, 6
#define TN_CHUNK 32
#define TARGET __attribute__((target("avx2,fma")))
#define WIDE 0
#define VMIN _mm256_min_ps
#define VMAX _mm256_max_ps
#define SET1 _mm256_set1_ps
#define VFMA(a, b, c) _mm256_fmadd_ps(a, b, c)
#include "_native_kernel.h"  /* undefines the parameters above */

/* -- AVX-512: 16 floats, 32 registers -------------------------------------- */
#define VW 16
#define SUFFIX avx512
/* the loop over K unrolled 4 times: 2 % faster here; slower on AVX2 and SSE2,
 * whose 16 registers it overfills */
#if defined(__clang__)
#define K_UNROLL _Pragma("unroll 4")
#else
#define K_UNROLL _Pragma("GCC unroll 4")
#endif
#define GEMM_NB_ROWS 4, 4
#define TN_NB_ROWS 4, 4
#define TN_CHUNK (1 << 30)  /* no chunks: 1 to 1.5 % slower in 32 to 96 rows */
#define TARGET __attribute__((target("avx512f,fma")))
#define WIDE 1
#define VMIN _mm512_min_ps
#define VMAX _mm512_max_ps
#define SET1 _mm512_set1_ps
#define VFMA(a, b, c) _mm512_fmadd_ps(a, b, c)
#include "_native_kernel.h"  /* undefines the parameters above */
#endif

#if ILOCI_X86
static int cpu_has_fma(void) {
    __builtin_cpu_init();
    return __builtin_cpu_supports("fma");
}
#endif

/* Whether this build and this CPU can run `isa` (ISA_AUTO: always). */
int iloci_rnnpb_isa_supported(int isa) {
    switch (isa) {
    case ISA_AUTO:
    case ISA_PORTABLE: return 1;
#if ILOCI_X86
    case ISA_AVX2:
        __builtin_cpu_init();
        return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
    case ISA_AVX512:
        __builtin_cpu_init();
        return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("fma");
#endif
    default: return 0;
    }
}

/* The instruction set ISA_AUTO runs: the widest this CPU has. */
int iloci_rnnpb_best_isa(void) {
    if (iloci_rnnpb_isa_supported(ISA_AVX512)) return ISA_AVX512;
    if (iloci_rnnpb_isa_supported(ISA_AVX2)) return ISA_AVX2;
    return ISA_PORTABLE;
}

/* sizeof the argument struct, so the caller can check its layout. */
int iloci_rnnpb_train_args_size(void) { return (int)sizeof(iloci_rnnpb_train_args); }

/* Entry point for ctypes (see rnnpb.py): the whole training. Returns OK (the
 * arrays updated, a->loss, epochs_run, isa_used set), NO_MEMORY, TOO_WIDE
 * (padded widths beyond WIDTH_MAX), ISA_UNSUPPORTED (the asked instruction
 * set is missing from the build or the CPU), or BAD_ARGS (a struct of
 * another layout, or sizes out of range). */
int iloci_rnnpb_train(iloci_rnnpb_train_args *a) {
    if (a == NULL || a->size != (int32_t)sizeof(*a)) return BAD_ARGS;
    if (a->epochs < 0 || a->T < 2 || a->R < 1 || a->D < 1 || a->C < 0 || a->H < 1
        || a->P < 1 || a->X == NULL || a->mw == NULL)
        return BAD_ARGS;
    if (round16(a->D + a->C) > WIDTH_MAX || round16(a->H) > WIDTH_MAX) return TOO_WIDE;
    int isa = a->isa == ISA_AUTO ? iloci_rnnpb_best_isa() : a->isa;
    if (!iloci_rnnpb_isa_supported(isa)) return ISA_UNSUPPORTED;
    a->isa_used = isa;
    a->epochs_run = 0;
    switch (isa) {
#if ILOCI_X86
    case ISA_AVX512: return train_avx512(a);
    case ISA_AVX2: return train_avx2(a);
    case ISA_PORTABLE:
        if (cpu_has_fma()) return train_portable_fma(a);
        return train_portable(a);
#endif
    default: return train_portable(a);
    }
}

/* sizeof the recognition's argument struct, so the caller can check its layout. */
int iloci_rnnpb_recognize_args_size(void) { return (int)sizeof(iloci_rnnpb_recognize_args); }

/* Entry point for ctypes: recognition_steps Levenberg-Marquardt steps on
 * every row's u at once. Returns OK (u and err set), NO_MEMORY, TOO_WIDE
 * (padded widths beyond WIDTH_MAX or more than LM_P_MAX PB units),
 * ISA_UNSUPPORTED or BAD_ARGS, as iloci_rnnpb_train. */
int iloci_rnnpb_recognize(iloci_rnnpb_recognize_args *a) {
    if (a == NULL || a->size != (int32_t)sizeof(*a)) return BAD_ARGS;
    if (a->steps < 0 || a->T < 2 || a->R < 1 || a->D < 1 || a->C < 0 || a->H < 1
        || a->P < 1 || a->X == NULL || a->sw == NULL || a->u == NULL)
        return BAD_ARGS;
    if (round16(a->D + a->C) > WIDTH_MAX || round16(a->H) > WIDTH_MAX || a->P > LM_P_MAX)
        return TOO_WIDE;
    int isa = a->isa == ISA_AUTO ? iloci_rnnpb_best_isa() : a->isa;
    if (!iloci_rnnpb_isa_supported(isa)) return ISA_UNSUPPORTED;
    a->isa_used = isa;
    switch (isa) {
#if ILOCI_X86
    case ISA_AVX512: return recognize_avx512(a);
    case ISA_AVX2: return recognize_avx2(a);
    case ISA_PORTABLE:
        if (cpu_has_fma()) return recognize_portable_fma(a);
        return recognize_portable(a);
#endif
    default: return recognize_portable(a);
    }
}

/* Entry point for ctypes: the closed-loop prediction error of every row under
 * its PB (see errors in _native_kernel.h for the fields it reads: a->u are
 * PBs, a->sw the mask, a->err receives the errors; steps, damping and the LM
 * constants are not read). Returns as iloci_rnnpb_recognize. */
int iloci_rnnpb_errors(iloci_rnnpb_recognize_args *a) {
    if (a == NULL || a->size != (int32_t)sizeof(*a)) return BAD_ARGS;
    if (a->T < 2 || a->R < 1 || a->D < 1 || a->C < 0 || a->H < 1 || a->P < 1
        || a->X == NULL || a->sw == NULL || a->u == NULL || a->err == NULL)
        return BAD_ARGS;
    if (round16(a->D + a->C) > WIDTH_MAX || round16(a->H) > WIDTH_MAX) return TOO_WIDE;
    int isa = a->isa == ISA_AUTO ? iloci_rnnpb_best_isa() : a->isa;
    if (!iloci_rnnpb_isa_supported(isa)) return ISA_UNSUPPORTED;
    a->isa_used = isa;
    switch (isa) {
#if ILOCI_X86
    case ISA_AVX512: return errors_avx512(a);
    case ISA_AVX2: return errors_avx2(a);
    case ISA_PORTABLE:
        if (cpu_has_fma()) return errors_portable_fma(a);
        return errors_portable(a);
#endif
    default: return errors_portable(a);
    }
}

/* ---- float64 closed-loop generation --------------------------------------
 *
 * RNNPBBase.generate (an entry's regenerated pattern: what the robot
 * performs, what the regeneration decision compares a drawing with, what a
 * rehearsal trains on) in float64, in the one order of operations that
 * iloci/rnnpb/float64.py writes in numpy (the spec; tested bit for bit):
 *
 *   - z[j] = (sum_k a[k] w[k, j]) + b[j]: acc = +0, k ascending,
 *     acc = acc + a[k] * w[k, j] (product rounded, then the sum: no fma;
 *     the module is compiled with -ffp-contract=off), then + b[j];
 *     pre = (sum_k pb[k] w_in[S + k]) + b_hidden once per row, each step's
 *     hidden pre-activation (sum_k s[k] w_in[k]) + pre over s = [x, c];
 *   - tanh64(x) = sign(x) e / (e + 2), e = expm1(2 |x|); 1 for |x| > 22;
 *     NaN for NaN;
 *   - expm1(y), 0 <= y <= 44: k = floor(y / ln2 + 1/2), r = (y - k ln2_hi) -
 *     k ln2_lo, p = r (1 + r (1/2! + r (... + r / 14!))) (Horner),
 *     2^k p + (2^k - 1) (a product with a power of 2: exact).
 *
 * Plain C, one function for every CPU: each operation is a correctly rounded
 * IEEE double operation, and a vector holds independent j, so the compiler's
 * vectorisation never changes a sum. numpy's BLAS (its kernels chosen by CPU
 * model) and numpy's tanh (SIMD code on AVX-512) do not give one result.
 */
static const double INV_LN2 = 1.4426950408889634;
static const double LN2_HI = 6.93147180369123816490e-01;
static const double LN2_LO = 1.90821492927058770002e-10;
static const double TANH_ONE = 22.0;

/* tanh64 on two lanes at once (GNU C vectors: one IEEE double operation per
 * lane, so the vector width changes no bit). Branch-free: floor, 2^k, |x|,
 * the sign and the selects are exact bit operations or exact additions:
 *   floor(v), 0 <= v < 2^51: f = (v + 2^52) - 2^52 (v to the nearest
 *     integer), minus 1 where f > v;
 *   2^k, 0 <= k <= 64: the bits of k + (1023 + 2^52) shifted left by 52. */
typedef double v2d __attribute__((vector_size(16)));
typedef int64_t v2l __attribute__((vector_size(16)));

static inline v2d v2d_select(v2l mask, v2d yes, v2d no) {
    return (v2d)((mask & (v2l)yes) | (~mask & (v2l)no));
}

static inline v2d tanh64_v2(v2d x) {
    /* 1/n! for n = 14 down to 2, rounded to double (as float64.EXPM1_COEFFICIENTS) */
    static const double c[13] = {1.0 / 87178291200.0, 1.0 / 6227020800.0, 1.0 / 479001600.0,
                                 1.0 / 39916800.0, 1.0 / 3628800.0, 1.0 / 362880.0,
                                 1.0 / 40320.0, 1.0 / 5040.0, 1.0 / 720.0, 1.0 / 120.0,
                                 1.0 / 24.0, 1.0 / 6.0, 1.0 / 2.0};
    const v2l sign = {INT64_MIN, INT64_MIN};
    const v2d one = {1.0, 1.0}, big = {TANH_ONE, TANH_ONE}, magic = {0x1p52, 0x1p52};
    v2d a = (v2d)((v2l)x & ~sign);
    v2d y = v2d_select(a < big, a, big) * 2.0;          /* NaN: TANH_ONE, replaced below */
    /* expm1(y), 0 <= y <= 44 */
    v2d v = y * INV_LN2 + 0.5;
    v2d f = (v + magic) - magic;
    v2d k = f - (v2d)((f > v) & (v2l)one);
    v2d r = (y - k * LN2_HI) - k * LN2_LO;
    v2d p = {c[0], c[0]};
    for (int i = 1; i < 13; i++) p = c[i] + r * p;
    p = 1.0 + r * p;
    p = r * p;
    v2d two_k = (v2d)((v2l)(k + (1023.0 + 0x1p52)) << 52);
    v2d e = p * two_k + (two_k - 1.0);
    v2d t = v2d_select(a > big, one, e / (e + 2.0));
    t = (v2d)(((v2l)t & ~sign) | ((v2l)x & sign));
    return v2d_select(x != x, x, t);
}

/* dst[j] = tanh64(src[j] + bias[j]), j < n (dst may be src) */
static void tanh64_add(double *dst, const double *src, const double *bias, int n) {
    int j = 0;
    for (; j + 1 < n; j += 2) {
        v2d z = {src[j] + bias[j], src[j + 1] + bias[j + 1]};
        v2d t = tanh64_v2(z);
        dst[j] = t[0];
        dst[j + 1] = t[1];
    }
    if (j < n) {
        v2d z = {src[j] + bias[j], 0.0};
        dst[j] = tanh64_v2(z)[0];
    }
}

/* Entry point for ctypes: out (steps, R, D) receives the closed-loop outputs
 * of R rows from PBs pbs (R, P) and first inputs x0 (R, D); the weights as
 * the reference holds them, float64, row-major: w_in (D + C + P, H),
 * b_hidden (H), w_out (H, D + C), b_out (D + C). Returns OK, NO_MEMORY or
 * BAD_ARGS. */
#if ILOCI_X86 && defined(__GNUC__) && !defined(__clang__)
/* also compiled for AVX2 and AVX-512 (chosen at load time): wider vectors of
 * the same per-lane operations, no fma (-ffp-contract=off), the same bits */
__attribute__((target_clones("avx512f", "avx2", "default")))
#endif
int iloci_rnnpb_generate64(int32_t R, int32_t D, int32_t C, int32_t H, int32_t P,
                           int32_t steps, const double *w_in, const double *b_hidden,
                           const double *w_out, const double *b_out, const double *pbs,
                           const double *x0, double *out) {
    if (R < 0 || D < 1 || C < 0 || H < 1 || P < 0 || steps < 0 || w_in == NULL
        || b_hidden == NULL || w_out == NULL || b_out == NULL || (R > 0 && (x0 == NULL
        || out == NULL || (P > 0 && pbs == NULL))))
        return BAD_ARGS;
    const int S = D + C;
    double *mem = malloc(sizeof(double) * (size_t)(2 * H + 2 * S));
    if (mem == NULL) return NO_MEMORY;
    double *pre = mem, *h = mem + H, *s = mem + 2 * H, *o = mem + 2 * H + S;
    for (int r = 0; r < R; r++) {
        for (int j = 0; j < H; j++) pre[j] = 0.0;
        for (int k = 0; k < P; k++) {
            const double a = pbs[(size_t)r * P + k], *w = w_in + (size_t)(S + k) * H;
            for (int j = 0; j < H; j++) pre[j] = pre[j] + a * w[j];
        }
        for (int j = 0; j < H; j++) pre[j] = pre[j] + b_hidden[j];
        for (int m = 0; m < S; m++) s[m] = m < D ? x0[(size_t)r * D + m] : 0.0;
        for (int t = 0; t < steps; t++) {
            for (int j = 0; j < H; j++) h[j] = 0.0;
            for (int k = 0; k < S; k++) {
                const double a = s[k], *w = w_in + (size_t)k * H;
                for (int j = 0; j < H; j++) h[j] = h[j] + a * w[j];
            }
            tanh64_add(h, h, pre, H);
            for (int m = 0; m < S; m++) o[m] = 0.0;
            for (int k = 0; k < H; k++) {
                const double a = h[k], *w = w_out + (size_t)k * S;
                for (int m = 0; m < S; m++) o[m] = o[m] + a * w[m];
            }
            tanh64_add(s, o, b_out, S);
            memcpy(out + ((size_t)t * R + r) * D, s, sizeof(double) * (size_t)D);
        }
    }
    free(mem);
    return OK;
}

#ifndef ILOCI_NATIVE_NO_PYTHON
/* A Python module only so that setuptools builds and installs the library;
 * the functions above are called through ctypes. */
static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_native",
                                    "native-rnnpb's kernel (called through ctypes: iloci_native.native).",
                                    -1, NULL, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__native(void) { return PyModule_Create(&module); }
#endif
