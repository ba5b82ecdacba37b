/*
 * torch-rnnpb's float32 training kernel in C with AVX-512: every epoch of
 * iloci_torch.rnnpb.TorchRNNPB.train (closed-loop forward pass, hand-written
 * BPTT, gradient clipping, Adam on the weights and on the PBs) in one call.
 *
 * Why: at paper size a training step is ~200 matrix products of 36 x 32 x 64.
 * Through torch each costs more to dispatch than to compute; here they are
 * register-blocked AVX-512 loops, and the whole training runs without
 * returning to Python. The algorithm and the update order are those of the
 * torch path in rnnpb.py (same formulas, float32 arithmetic, different
 * rounding); tests compare the two.
 *
 * Only the functions marked TARGET use AVX-512. The module is compiled
 * without -march flags and iloci_rnnpb_native_supported() asks the CPU at run
 * time, so a build made here never executes an unsupported instruction
 * elsewhere: the caller falls back to the torch path.
 *
 * Layout: weights are padded inside to S_p = roundup16(D + C) state and
 * H_p = roundup16(H) hidden columns (whole 16-float registers). Padded units
 * stay exactly zero: their weights start at zero, their pre-activations are
 * zero, tanh(0) = 0, and their gradients (hence Adam updates) are zero.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <math.h>
#include <stdlib.h>
#include <string.h>

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define ILOCI_HAVE_AVX512 1
#include <immintrin.h>
#define TARGET __attribute__((target("avx512f,fma")))
#define INLINE static inline __attribute__((always_inline))
#else
#define ILOCI_HAVE_AVX512 0
#endif

/* Largest padded widths the register-blocked loops handle (H <= 128, D + C <= 128). */
#define NV_MAX 8

int iloci_rnnpb_native_supported(void) {
#if ILOCI_HAVE_AVX512
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("fma");
#else
    return 0;
#endif
}

#if ILOCI_HAVE_AVX512

/* tanh in float32: a [13/6] rational approximation on [-7.9, 7.9] (the one
 * Eigen and XLA use; beyond, tanh rounds to +-1), the division done as a
 * reciprocal estimate refined by one Newton step. */
TARGET INLINE __m512 vtanh(__m512 x) {
    const __m512 c = _mm512_set1_ps(7.90531110763549805f);
    x = _mm512_min_ps(_mm512_max_ps(x, _mm512_sub_ps(_mm512_setzero_ps(), c)), c);
    __m512 x2 = _mm512_mul_ps(x, x);
    __m512 p = _mm512_fmadd_ps(x2, _mm512_set1_ps(-2.76076847742355e-16f),
                               _mm512_set1_ps(2.00018790482477e-13f));
    p = _mm512_fmadd_ps(x2, p, _mm512_set1_ps(-8.60467152213735e-11f));
    p = _mm512_fmadd_ps(x2, p, _mm512_set1_ps(5.12229709037114e-08f));
    p = _mm512_fmadd_ps(x2, p, _mm512_set1_ps(1.48572235717979e-05f));
    p = _mm512_fmadd_ps(x2, p, _mm512_set1_ps(6.37261928875436e-04f));
    p = _mm512_fmadd_ps(x2, p, _mm512_set1_ps(4.89352455891786e-03f));
    p = _mm512_mul_ps(x, p);
    __m512 q = _mm512_fmadd_ps(x2, _mm512_set1_ps(1.19825839466702e-06f),
                               _mm512_set1_ps(1.18534705686654e-04f));
    q = _mm512_fmadd_ps(x2, q, _mm512_set1_ps(2.26843463243900e-03f));
    q = _mm512_fmadd_ps(x2, q, _mm512_set1_ps(4.89352518554385e-03f));
    __m512 r = _mm512_rcp14_ps(q);
    r = _mm512_mul_ps(r, _mm512_fnmadd_ps(q, r, _mm512_set1_ps(2.0f)));
    return _mm512_mul_ps(p, r);
}

enum { EPI_NONE = 0, EPI_TANH = 1, EPI_DTANH = 2 };

/* C[i, :] = epi(init_i + A[i, :K] @ B) for the first M - M % ROWS rows;
 * returns how many rows it did. N = 16 nv columns. init_i: C's own row
 * (acc), a row of `init` (stride init_stride; 0 = one row vector for every
 * i) or zero. EPI_DTANH multiplies by 1 - E[i, :]^2 (the derivative of the
 * tanh whose outputs E holds). ROWS rows at a time keep ROWS * nv
 * independent FMA chains in registers. */
TARGET INLINE int gemm_block(int M, int K, const int nv, const int ROWS,
                             const float *A, int lda, const float *B,
                             const float *init, int init_stride, int acc,
                             float *C, int epi, const float *E) {
    const int N = 16 * nv;
    int i = 0;
    for (; i + ROWS <= M; i += ROWS) {
        __m512 c[4][NV_MAX];
        for (int q = 0; q < ROWS; q++)
            for (int v = 0; v < nv; v++)
                c[q][v] = acc ? _mm512_loadu_ps(C + (i + q) * N + 16 * v)
                        : init ? _mm512_loadu_ps(init + (i + q) * init_stride + 16 * v)
                        : _mm512_setzero_ps();
        for (int k = 0; k < K; k++) {
            const float *b = B + k * N;
            __m512 bv[NV_MAX];
            for (int v = 0; v < nv; v++) bv[v] = _mm512_loadu_ps(b + 16 * v);
            for (int q = 0; q < ROWS; q++) {
                __m512 a = _mm512_set1_ps(A[(i + q) * lda + k]);
                for (int v = 0; v < nv; v++) c[q][v] = _mm512_fmadd_ps(a, bv[v], c[q][v]);
            }
        }
        for (int q = 0; q < ROWS; q++)
            for (int v = 0; v < nv; v++) {
                __m512 y = c[q][v];
                if (epi == EPI_TANH) y = vtanh(y);
                else if (epi == EPI_DTANH) {
                    __m512 e = _mm512_loadu_ps(E + (i + q) * N + 16 * v);
                    y = _mm512_mul_ps(y, _mm512_fnmadd_ps(e, e, _mm512_set1_ps(1.0f)));
                }
                _mm512_storeu_ps(C + (i + q) * N + 16 * v, y);
            }
    }
    return i;
}

/* Dispatch with nv and ROWS as constants, so the loops above unroll into
 * registers for the common widths (the paper's: 32 and 64 columns); the
 * last M % ROWS rows go one at a time. */
#define GEMM_CASE(NV, ROWS) do { \
        done = gemm_block(M, K, NV, ROWS, A, lda, B, init, init_stride, acc, C, epi, E); \
        if (done < M) \
            gemm_block(M - done, K, NV, 1, A + done * lda, lda, B, \
                       init ? init + done * init_stride : NULL, init_stride, acc, \
                       C + done * N, epi, E ? E + done * N : NULL); \
    } while (0)

TARGET static void gemm(int M, int K, int N, const float *A, int lda, const float *B,
                        const float *init, int init_stride, int acc, float *C,
                        int epi, const float *E) {
    int done;
    switch (N / 16) {
    case 1: GEMM_CASE(1, 4); break;
    case 2: GEMM_CASE(2, 4); break;
    case 3: GEMM_CASE(3, 2); break;
    case 4: GEMM_CASE(4, 2); break;
    default: gemm_block(M, K, N / 16, 1, A, lda, B, init, init_stride, acc, C, epi, E); break;
    }
}

/* W[K, N] += A[M, :K]^T @ B[M, N] (weight gradients: a sum over all steps and
 * rows) for the first K - K % IB rows of W; returns how many. IB rows of W
 * per pass keep IB * nv accumulators in registers. */
TARGET INLINE int gemm_tn_block(int M, int K, const int nv, const int IB,
                                const float *A, int lda, const float *B, float *W) {
    const int N = 16 * nv;
    int i0 = 0;
    for (; i0 + IB <= K; i0 += IB) {
        __m512 c[16][NV_MAX];
        for (int q = 0; q < IB; q++)
            for (int v = 0; v < nv; v++) c[q][v] = _mm512_loadu_ps(W + (i0 + q) * N + 16 * v);
        for (int r = 0; r < M; r++) {
            __m512 bv[NV_MAX];
            for (int v = 0; v < nv; v++) bv[v] = _mm512_loadu_ps(B + r * N + 16 * v);
            const float *a = A + r * lda + i0;
            for (int q = 0; q < IB; q++) {
                __m512 x = _mm512_set1_ps(a[q]);
                for (int v = 0; v < nv; v++) c[q][v] = _mm512_fmadd_ps(x, bv[v], c[q][v]);
            }
        }
        for (int q = 0; q < IB; q++)
            for (int v = 0; v < nv; v++) _mm512_storeu_ps(W + (i0 + q) * N + 16 * v, c[q][v]);
    }
    return i0;
}

#define GEMM_TN_CASE(NV, IB) do { \
        done = gemm_tn_block(M, K, NV, IB, A, lda, B, W); \
        if (done < K) gemm_tn_block(M, K - done, NV, 1, A + done, lda, B, W + done * N); \
    } while (0)

TARGET static void gemm_tn(int M, int K, int N, const float *A, int lda, const float *B,
                           float *W) {
    int done;
    switch (N / 16) {
    case 1: GEMM_TN_CASE(1, 16); break;
    case 2: GEMM_TN_CASE(2, 8); break;
    case 3: GEMM_TN_CASE(3, 4); break;
    case 4: GEMM_TN_CASE(4, 4); break;
    default: gemm_tn_block(M, K, N / 16, 1, A, lda, B, W); break;
    }
}

static void adam(float *p, const float *g, float *m, float *v, size_t n, double lr, int t,
                 float scale) {
    const float b1 = 0.9f, b2 = 0.999f;
    const float step = (float)(lr * sqrt(1.0 - pow(0.999, t)) / (1.0 - pow(0.9, t)));
    for (size_t i = 0; i < n; i++) {
        float gi = g[i] * scale;
        m[i] = b1 * m[i] + (1.0f - b1) * gi;
        v[i] = b2 * v[i] + (1.0f - b2) * gi * gi;
        p[i] -= step * m[i] / (sqrtf(v[i]) + 1e-8f);
    }
}

static int round16(int n) { return (n + 15) / 16 * 16; }

/* The whole training. Returns 0, or 1 when out of memory, 2 for sizes beyond
 * NV_MAX (the caller then uses the torch path). Arrays are C-contiguous
 * float32: X (T, R, D) padded sequences; mw (T - 1, R) mask times each row's
 * loss weight; w_in (D + C + P, H), b_hidden (H), w_out (H, D + C), b_out
 * (D + C), u (R, P) with PB = bound tanh(u): all updated in place. */
TARGET static int train_avx512(int epochs, int T, int R, int D, int Cn, int H, int P,
                               const float *X, const float *mw, float alpha,
                               float *w_in, float *b_hidden, float *w_out, float *b_out,
                               float *u, double lr, double pb_lr, double decay, int warmup,
                               double clip, float bound, float *loss_out) {
    const int S = D + Cn, Sp = round16(S), Hp = round16(H), L = T - 1;
    if (Sp / 16 > NV_MAX || Hp / 16 > NV_MAX) return 2;
    /* flat padded parameters: Ws (Sp, Hp) | Wp (P, Hp) | bh (Hp) | Wo (Hp, Sp) | bo (Sp) */
    const size_t nWs = (size_t)Sp * Hp, nWp = (size_t)P * Hp, nWo = (size_t)Hp * Sp;
    const size_t nW = nWs + nWp + Hp + nWo + Sp, nU = (size_t)R * P;
    const size_t LR = (size_t)L * R;
    size_t total = 4 * nW + 4 * nU          /* params, grads, Adam m, v; u's grad, m, v, pb */
                   + LR * Hp * 2 + LR * Sp * 2   /* H, DZ, O, G */
                   + (alpha != 1.0f ? LR * Sp : 0) /* IN when teacher-forced in part */
                   + (size_t)R * Sp + (size_t)R * Hp * 2 + nWs + nWo + Sp;
    float *mem = (float *)calloc(total, sizeof(float));
    if (!mem) return 1;
    float *w = mem, *g = w + nW, *m = g + nW, *v = m + nW;
    float *gu = v + nW, *mu = gu + nU, *vu = mu + nU, *pb = vu + nU;
    float *Hs = pb + nU, *DZ = Hs + LR * Hp, *Os = DZ + LR * Hp, *G = Os + LR * Sp;
    float *IN = alpha != 1.0f ? G + LR * Sp : NULL;
    float *s0 = (IN ? IN + LR * Sp : G + LR * Sp), *pre = s0 + (size_t)R * Sp;
    float *sdz = pre + (size_t)R * Hp, *WoT = sdz + (size_t)R * Hp, *WsTm = WoT + nWo;
    float *mix = WsTm + nWs;
    float *Ws = w, *Wp = Ws + nWs, *bh = Wp + nWp, *Wo = bh + Hp, *bo = Wo + nWo;
    float *gWs = g, *gWp = gWs + nWs, *gbh = gWp + nWp, *gWo = gbh + Hp, *gbo = gWo + nWo;

    for (int j = 0; j < S; j++) {
        for (int h = 0; h < H; h++) Ws[j * Hp + h] = w_in[j * H + h];
        bo[j] = b_out[j];
        mix[j] = j < D ? alpha : 1.0f;
    }
    for (int k = 0; k < P; k++)
        for (int h = 0; h < H; h++) Wp[k * Hp + h] = w_in[(S + k) * H + h];
    for (int h = 0; h < H; h++) {
        bh[h] = b_hidden[h];
        for (int j = 0; j < S; j++) Wo[h * Sp + j] = w_out[h * S + j];
    }
    for (int r = 0; r < R; r++)
        for (int j = 0; j < D; j++) s0[r * Sp + j] = X[r * D + j];

    float loss = 0.0f;
    for (int t = 1; t <= epochs; t++) {
        /* PB = bound tanh(u); pre = PB @ Wp + bh: the same every step */
        for (size_t i = 0; i < nU; i++) pb[i] = bound * tanhf(u[i]);
        for (int r = 0; r < R; r++)
            for (int h = 0; h < Hp; h++) {
                float a = bh[h];
                for (int k = 0; k < P; k++) a += pb[r * P + k] * Wp[k * Hp + h];
                pre[r * Hp + h] = a;
            }
        /* forward: s_0 = [x_0, 0]; s_t = o_{t-1} mix + (1 - alpha) [x_t, 0] */
        for (int s = 0; s < L; s++) {
            const float *in = s0;
            if (s > 0 && IN) {
                float *row = IN + (size_t)s * R * Sp;
                const float *o = Os + (size_t)(s - 1) * R * Sp;
                for (int r = 0; r < R; r++)
                    for (int j = 0; j < Sp; j++)
                        row[r * Sp + j] = o[r * Sp + j] * (j < S ? mix[j] : 0.0f)
                            + (j < D ? (1.0f - alpha) * X[((size_t)s * R + r) * D + j] : 0.0f);
                in = row;
            } else if (s > 0) {
                in = Os + (size_t)(s - 1) * R * Sp;
            }
            float *h = Hs + (size_t)s * R * Hp;
            gemm(R, Sp, Hp, in, Sp, Ws, pre, Hp, 0, h, EPI_TANH, NULL);
            gemm(R, Hp, Sp, h, Hp, Wo, bo, 0, 0, Os + (size_t)s * R * Sp, EPI_TANH, NULL);
        }
        /* loss = sum mw mean_D (y - x)^2; G = dL/do */
        double lsum = 0.0;
        memset(G, 0, LR * Sp * sizeof(float));
        for (size_t i = 0; i < LR; i++) {
            const float *o = Os + i * Sp, *x = X + (i + R) * D;
            float wgt = mw[i], part = 0.0f;
            for (int j = 0; j < D; j++) {
                float d = o[j] - x[j];
                part += d * d;
                G[i * Sp + j] = d * wgt * (2.0f / D);
            }
            lsum += (double)(part * wgt);
        }
        loss = (float)(lsum / D);
        /* backward: go_t = (G_t + carry) (1 - o_t^2); dz_t = (go_t Wo^T) (1 - h_t^2);
           carry into G_{t-1} = dz_t (mix Ws)^T, since s_t holds o_{t-1} mix */
        for (int h = 0; h < Hp; h++)
            for (int j = 0; j < Sp; j++) {
                WoT[j * Hp + h] = Wo[h * Sp + j];
                WsTm[h * Sp + j] = Ws[j * Hp + h] * (j < S ? mix[j] : 0.0f);
            }
        for (int s = L - 1; s >= 0; s--) {
            float *go = G + (size_t)s * R * Sp;
            const float *o = Os + (size_t)s * R * Sp;
            for (int i = 0; i < R * Sp; i++) go[i] *= 1.0f - o[i] * o[i];
            float *dz = DZ + (size_t)s * R * Hp;
            gemm(R, Sp, Hp, go, Sp, WoT, NULL, 0, 0, dz, EPI_DTANH, Hs + (size_t)s * R * Hp);
            if (s > 0) gemm(R, Hp, Sp, dz, Hp, WsTm, NULL, 0, 1, go - (size_t)R * Sp,
                            EPI_NONE, NULL);
        }
        /* weight gradients: sums over all steps and rows */
        memset(g, 0, nW * sizeof(float));
        memset(sdz, 0, (size_t)R * Hp * sizeof(float));
        gemm_tn((int)LR, Hp, Sp, Hs, Hp, G, gWo);
        gemm_tn(R, Sp, Hp, s0, Sp, DZ, gWs);
        if (L > 1)
            gemm_tn((int)(LR - R), Sp, Hp, IN ? IN + (size_t)R * Sp : Os, Sp,
                    DZ + (size_t)R * Hp, gWs);
        for (size_t i = 0; i < LR; i++)
            for (int j = 0; j < Sp; j++) gbo[j] += G[i * Sp + j];
        for (size_t i = 0; i < LR; i++)
            for (int h = 0; h < Hp; h++) sdz[(i % R) * Hp + h] += DZ[i * Hp + h];
        for (int r = 0; r < R; r++)
            for (int h = 0; h < Hp; h++) {
                gbh[h] += sdz[r * Hp + h];
                for (int k = 0; k < P; k++) gWp[k * Hp + h] += pb[r * P + k] * sdz[r * Hp + h];
            }
        /* dL/du = (sdz Wp^T) bound (1 - tanh(u)^2) */
        for (int r = 0; r < R; r++)
            for (int k = 0; k < P; k++) {
                float a = 0.0f;
                for (int h = 0; h < Hp; h++) a += sdz[r * Hp + h] * Wp[k * Hp + h];
                float th = tanhf(u[r * P + k]);
                gu[r * P + k] = a * bound * (1.0f - th * th);
            }
        /* clip the weight gradient's global norm, then Adam */
        double sq = 0.0;
        for (size_t i = 0; i < nW; i++) sq += (double)g[i] * g[i];
        double scale = clip / (sqrt(sq) + 1e-12);
        if (scale > 1.0) scale = 1.0;
        double f = pow(decay, (double)(t - 1) / epochs);
        double ramp = warmup > 0 ? (t < warmup ? (double)t / warmup : 1.0) : 1.0;
        adam(w, g, m, v, nW, lr * f * ramp, t, (float)scale);
        adam(u, gu, mu, vu, nU, pb_lr * f, t, 1.0f);
    }

    for (int j = 0; j < S; j++) {
        for (int h = 0; h < H; h++) w_in[j * H + h] = Ws[j * Hp + h];
        b_out[j] = bo[j];
    }
    for (int k = 0; k < P; k++)
        for (int h = 0; h < H; h++) w_in[(S + k) * H + h] = Wp[k * Hp + h];
    for (int h = 0; h < H; h++) {
        b_hidden[h] = bh[h];
        for (int j = 0; j < S; j++) w_out[h * S + j] = Wo[h * Sp + j];
    }
    *loss_out = loss;
    free(mem);
    return 0;
}
#endif

/* Entry point for ctypes (see rnnpb.py). Returns 3 when the CPU or the
 * build has no AVX-512; otherwise as train_avx512. */
int iloci_rnnpb_train_f32(int epochs, int T, int R, int D, int C, int H, int P,
                          const float *X, const float *mw, float alpha,
                          float *w_in, float *b_hidden, float *w_out, float *b_out, float *u,
                          double lr, double pb_lr, double decay, int warmup, double clip,
                          float bound, float *loss_out) {
#if ILOCI_HAVE_AVX512
    if (!iloci_rnnpb_native_supported()) return 3;
    return train_avx512(epochs, T, R, D, C, H, P, X, mw, alpha, w_in, b_hidden, w_out, b_out,
                        u, lr, pb_lr, decay, warmup, clip, bound, loss_out);
#else
    (void)epochs; (void)T; (void)R; (void)D; (void)C; (void)H; (void)P; (void)X; (void)mw;
    (void)alpha; (void)w_in; (void)b_hidden; (void)w_out; (void)b_out; (void)u; (void)lr;
    (void)pb_lr; (void)decay; (void)warmup; (void)clip; (void)bound; (void)loss_out;
    return 3;
#endif
}

/* A Python module only so that setuptools builds and installs the library;
 * the functions above are called through ctypes. */
static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_native",
                                    "torch-rnnpb's native training kernel (see rnnpb.py).",
                                    -1, NULL, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__native(void) { return PyModule_Create(&module); }
