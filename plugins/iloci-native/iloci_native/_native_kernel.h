/*
 * The training kernel of _native.c, written once over a vector width and
 * compiled once per instruction set: _native.c includes this file with
 *
 *   VW      floats per vector register (16: AVX-512, 8: AVX2, 4: portable)
 *   SUFFIX  appended to every name defined here (avx512, avx2, portable)
 *   TARGET  the function attribute selecting the instruction set (empty for
 *           the portable path: the compiler's default for the platform)
 *   VFMA(a, b, c)  a b + c on vectors, fused (one rounding): the instruction
 *           set's fused multiply-add, or fmaf lane by lane where it has none
 *   WIDE    1 where there are 32 vector registers (AVX-512): larger tiles
 *   GEMM_NB_ROWS, TN_NB_ROWS  the register tiles (see _native.c)
 *   TN_CHUNK  rows of the weight gradients' sums per pass over W's tiles
 *   VMIN, VMAX  the instruction set's element-wise min and max, where it has
 *           them (otherwise a compare and a blend)
 *   SET1    the instruction set's broadcast of a float, where it has one
 *   K_UNROLL  a pragma unrolling the products' loop over K, or nothing
 *
 * The arithmetic is GNU C vector extensions (GCC, Clang): the compiler maps
 * them to the target's registers, so the portable path is the same source
 * as the AVX paths, vectorized for SSE on x86-64, NEON on aarch64, or
 * split into scalars where there is no vector unit. The element-wise loops
 * are plain C, vectorized by -O3.
 *
 * One arithmetic on every path (see "The float32 arithmetic" in _native.c):
 * every element's sums run in the same order whatever the vector width
 * (a vector holds VW independent columns, never parts of one sum), the
 * matrix and dot products' steps are explicit fused multiply-adds (VFMA,
 * fmaf), every other operation is separately rounded IEEE (the module is
 * compiled with -ffp-contract=off, so the compiler fuses nothing on its
 * own), and tanh is our own rational function with a true division. So
 * AVX-512, AVX2, SSE and NEON round identically: bit-identical results.
 */

#define CAT_(a, b) a##_##b
#define CAT(a, b) CAT_(a, b)
#define F(name) CAT(name, SUFFIX)
#define V F(vf)
#define VU F(vfu)
#define VI F(vi)
#define INL TARGET static inline __attribute__((always_inline))
#define FIRST_(a, b) a
#define SECOND_(a, b) b
#define FIRST(x) FIRST_(x)
#define SECOND(x) SECOND_(x)
#define GEMM_NB FIRST(GEMM_NB_ROWS)
#define GEMM_ROWS SECOND(GEMM_NB_ROWS)
#define TN_NB FIRST(TN_NB_ROWS)
#define TN_ROWS SECOND(TN_NB_ROWS)

typedef float V __attribute__((vector_size(VW * 4)));
/* the same, for loads and stores at any float-aligned address */
typedef float VU __attribute__((vector_size(VW * 4), aligned(4), may_alias));
typedef int32_t VI __attribute__((vector_size(VW * 4)));

#define LD(p) ((V)*(const VU *)(p))
#define ST(p, x) (*(VU *)(p) = (x))

/* a in every lane: the instruction set's broadcast where it names one.
 * Not `(V){0} + a` there: that is a real addition (0 + -0 is +0), one more
 * instruction per broadcast in the products' inner loops (the AVX-512 step
 * took 0.54 ms instead of 0.5x, measured here). */
#ifdef SET1
INL V F(splat)(float a) { return (V)SET1(a); }
#else
INL V F(splat)(float a) {  /* not (V){0} + a: 0 + -0 is +0 */
    V r;
    for (int i = 0; i < VW; i++) r[i] = a;
    return r;
}
#endif

/* a b + c rounded once, lane by lane */
INL V F(vfma)(V a, V b, V c) { return (V)VFMA(a, b, c); }

#ifdef VMIN
INL V F(vmin)(V a, V b) { return (V)VMIN(a, b); }
INL V F(vmax)(V a, V b) { return (V)VMAX(a, b); }
#else
INL V F(vmin)(V a, V b) { VI m = a < b; return (V)((m & (VI)a) | (~m & (VI)b)); }
INL V F(vmax)(V a, V b) { VI m = a > b; return (V)((m & (VI)a) | (~m & (VI)b)); }
#endif

/* tanh in float32: a [13/6] rational approximation on [-7.9, 7.9] (the one
 * Eigen and XLA use; beyond, tanh rounds to +-1), Horner steps fused, one
 * correctly rounded division: the same bits on every instruction set (no
 * reciprocal estimate, whose bits differ between AVX2's rcpps and
 * AVX-512's rcp14ps). */
#define TANH_CLAMP 7.90531110763549805f
#define TANH_P(x2, FMA, K) \
    FMA(x2, FMA(x2, FMA(x2, FMA(x2, FMA(x2, FMA(x2, K(-2.76076847742355e-16f), \
        K(2.00018790482477e-13f)), K(-8.60467152213735e-11f)), K(5.12229709037114e-08f)), \
        K(1.48572235717979e-05f)), K(6.37261928875436e-04f)), K(4.89352455891786e-03f))
#define TANH_Q(x2, FMA, K) \
    FMA(x2, FMA(x2, FMA(x2, K(1.19825839466702e-06f), K(1.18534705686654e-04f)), \
        K(2.26843463243900e-03f)), K(4.89352518554385e-03f))
INL V F(vtanh)(V x) {
    const V c = F(splat)(TANH_CLAMP);
    x = F(vmin)(F(vmax)(x, -c), c);
    V x2 = x * x;
    V p = TANH_P(x2, F(vfma), F(splat));
    V q = TANH_Q(x2, F(vfma), F(splat));
    return (x * p) / q;
}

/* The same function on one float (the PBs' tanh): the same operations in
 * the same order, so the same bits as a lane of vtanh. */
#define KF(a) (a)
INL float F(stanh)(float x) {
    x = x < -TANH_CLAMP ? -TANH_CLAMP : x > TANH_CLAMP ? TANH_CLAMP : x;
    float x2 = x * x;
    float p = TANH_P(x2, __builtin_fmaf, KF);
    float q = TANH_Q(x2, __builtin_fmaf, KF);
    return (x * p) / q;
}
#undef KF
#undef TANH_P
#undef TANH_Q
#undef TANH_CLAMP

/* C[i, :NB VW] = epi(init_i + A[i, :K] @ B[:, :NB VW]) for the first
 * M - M % ROWS rows; returns how many rows it did. B, C, E and init point
 * at the column block's first column; ldn is their row stride (the full
 * width). init_i: C's own row (acc), a row of `init` (row stride
 * init_stride; 0 = the same row for every i) or zero. EPI_DTANH multiplies
 * by 1 - E[i, :]^2 (the derivative of the tanh whose outputs E holds).
 * ROWS x NB accumulators stay in registers.
 *
 * Indices and strides are ptrdiff_t, not int: with int, `(i + q) * ldn`
 * under -fwrapv (in the CFLAGS Python passes to extensions) may not be
 * rewritten as pointer increments, and the AVX2 step took 0.93 ms instead
 * of 0.66 (GCC 12, paper size, measured here). */
INL ptrdiff_t F(gemm_tile)(ptrdiff_t M, ptrdiff_t K, const int NB, const int ROWS,
                           const float *A, ptrdiff_t lda, const float *B, ptrdiff_t ldn,
                           const float *init, ptrdiff_t init_stride, int acc, float *C,
                           int epi, const float *E) {
    ptrdiff_t i = 0;
    for (; i + ROWS <= M; i += ROWS) {
        V c[8][4];
        for (int q = 0; q < ROWS; q++)
            for (int v = 0; v < NB; v++)
                c[q][v] = acc ? LD(C + (i + q) * ldn + VW * v)
                        : init ? LD(init + (i + q) * init_stride + VW * v)
                        : F(splat)(0.0f);
        K_UNROLL
        for (ptrdiff_t k = 0; k < K; k++) {
            const float *b = B + k * ldn;
            V bv[4];
            for (int v = 0; v < NB; v++) bv[v] = LD(b + VW * v);
            for (int q = 0; q < ROWS; q++) {
                V a = F(splat)(A[(i + q) * lda + k]);
                for (int v = 0; v < NB; v++) c[q][v] = F(vfma)(a, bv[v], c[q][v]);
            }
        }
        for (int q = 0; q < ROWS; q++)
            for (int v = 0; v < NB; v++) {
                V y = c[q][v];
                if (epi == EPI_TANH) y = F(vtanh)(y);
                else if (epi == EPI_DTANH) {
                    V e = LD(E + (i + q) * ldn + VW * v);
                    y = y * F(vfma)(-e, e, F(splat)(1.0f));
                }
                ST(C + (i + q) * ldn + VW * v, y);
            }
    }
    return i;
}

/* Rows [r0, r0 + M) of one column block in tiles of ROWS rows; returns how many it did. */
#define GEMM_ROWS_AT(r0, M, NB, ROWS) \
    ((r0) + F(gemm_tile)((M), K, NB, ROWS, A + (r0) * lda, lda, B + col, N, \
                         init ? init + (r0) * init_stride + col : NULL, init_stride, acc, \
                         C + (r0) * N + col, epi, E ? E + (r0) * N + col : NULL))

/* One column block of gemm: the rows in tiles of ROWS, the rest in tiles of
 * 2 then 1 (one row has NB accumulators only, each waiting on its last fused
 * multiply-add: half the throughput); with 3-row tiles, a last single row
 * goes with the tile before it as 2 + 2. Every element's sum is the same
 * whatever tile computes it. */
#define GEMM_TILE(NB, ROWS) do { \
        ptrdiff_t full = M / (ROWS) * (ROWS); \
        if ((ROWS) == 3 && M - full == 1 && full > 0) full -= 3; \
        ptrdiff_t done = GEMM_ROWS_AT(0, full, NB, ROWS); \
        done = GEMM_ROWS_AT(done, M - done, NB, 2); \
        if (done < M) GEMM_ROWS_AT(done, M - done, NB, 1); \
        col += (NB) * VW; \
    } while (0)

/* C[M, N] = epi(init + A[M, :K] @ B[K, N]), N a multiple of VW: column
 * blocks of 4, 2 or 1 vectors with 2, 4 or 4 rows per tile (twice the rows
 * with 32 registers). */
TARGET static void F(gemm)(int M, int K, int N, const float *A, int lda, const float *B,
                           const float *init, int init_stride, int acc, float *C, int epi,
                           const float *E) {
    int col = 0;
    while (N - col >= GEMM_NB * VW) GEMM_TILE(GEMM_NB, GEMM_ROWS);
    if (N - col >= 2 * VW) GEMM_TILE(2, 4);
    if (N - col >= VW) GEMM_TILE(1, 4);
}

/* W[i0 .., :NB VW] (+)= A[M, i0 ..]^T @ B[M, :NB VW] (weight gradients: a
 * sum over all steps and rows) for the first K - K % IB rows of W; returns
 * how many. B and W point at the column block; ldn is their row stride.
 * acc: add to W; otherwise overwrite it (the same sums as adding to zeros). */
INL ptrdiff_t F(gemm_tn_tile)(ptrdiff_t M, ptrdiff_t K, const int NB, const int IB,
                              const float *A, ptrdiff_t lda, const float *B, ptrdiff_t ldn,
                              int acc, float *W) {
    ptrdiff_t i0 = 0;
    for (; i0 + IB <= K; i0 += IB) {
        V c[16][8];
        for (int q = 0; q < IB; q++)
            for (int v = 0; v < NB; v++)
                c[q][v] = acc ? LD(W + (i0 + q) * ldn + VW * v) : F(splat)(0.0f);
        for (ptrdiff_t r = 0; r < M; r++) {
            V bv[8];
            for (int v = 0; v < NB; v++) bv[v] = LD(B + r * ldn + VW * v);
            const float *a = A + r * lda + i0;
            for (int q = 0; q < IB; q++) {
                V x = F(splat)(a[q]);
                for (int v = 0; v < NB; v++) c[q][v] = F(vfma)(x, bv[v], c[q][v]);
            }
        }
        for (int q = 0; q < IB; q++)
            for (int v = 0; v < NB; v++) ST(W + (i0 + q) * ldn + VW * v, c[q][v]);
    }
    return i0;
}

#define GEMM_TN_TILE(NB, IB) do { \
        ptrdiff_t done = F(gemm_tn_tile)(M, K, NB, IB, A, lda, B + col, N, acc, W + col); \
        if (done < K) \
            F(gemm_tn_tile)(M, K - done, NB, 1, A + done, lda, B + col, N, acc, \
                            W + done * N + col); \
        col += (NB) * VW; \
    } while (0)

/* Rows [k0, K) of W over its columns [0, ncol), one row at a time, up to 8
 * vectors of columns per pass (the main tiles' leftover rows: 8
 * independent sums per row rather than TN_NB). */
#define GEMM_TN_LEFT(k0, ncol) do { \
        int c0 = 0; \
        for (; (ncol) - c0 >= 8 * VW; c0 += 8 * VW) \
            F(gemm_tn_tile)(M, K - (k0), 8, 1, A + (k0), lda, B + c0, N, acc, W + (k0) * N + c0); \
        for (; (ncol) - c0 >= 4 * VW; c0 += 4 * VW) \
            F(gemm_tn_tile)(M, K - (k0), 4, 1, A + (k0), lda, B + c0, N, acc, W + (k0) * N + c0); \
        for (; (ncol) - c0 >= VW; c0 += VW) \
            F(gemm_tn_tile)(M, K - (k0), 1, 1, A + (k0), lda, B + c0, N, acc, W + (k0) * N + c0); \
    } while (0)

/* W[K, N] (+)= A[M, :K]^T @ B[M, N], N a multiple of VW; acc as gemm_tn_tile.
 * The rows go in chunks of TN_CHUNK: every tile of W passes over a chunk
 * while it is in the L1 cache, instead of each tile streaming all M rows
 * from L2 (each sum still runs over the rows in order: same results). */
TARGET static void F(gemm_tn)(int M_all, int K, int N, const float *A_all, int lda,
                              const float *B_all, int acc_all, float *W) {
    for (int m0 = 0; m0 < M_all; m0 += TN_CHUNK) {
        const int M = M_all - m0 < TN_CHUNK ? M_all - m0 : TN_CHUNK;
        const float *A = A_all + (ptrdiff_t)m0 * lda, *B = B_all + (ptrdiff_t)m0 * N;
        const int acc = acc_all || m0 > 0;
        int col = 0;
        const ptrdiff_t kmain = K / TN_ROWS * TN_ROWS;
        while (N - col >= TN_NB * VW) {
            F(gemm_tn_tile)(M, kmain, TN_NB, TN_ROWS, A, lda, B + col, N, acc, W + col);
            col += TN_NB * VW;
        }
        if (kmain < K) GEMM_TN_LEFT(kmain, col);
        if (N - col >= 2 * VW) GEMM_TN_TILE(2, 4 * (1 + WIDE));
        if (N - col >= VW) GEMM_TN_TILE(1, 8 * (1 + WIDE));
    }
}

/* dst[:N] = sum over i < M of src[i * lds, :N], N a multiple of VW, i in
 * ascending order (the order of the scalar loop it replaces: same sums).
 * Up to 8 vectors of columns at a time stay in registers (a scalar loop
 * adding into dst kept one sum in memory, reloaded every row). */
TARGET static void F(colsum)(ptrdiff_t M, int N, const float *src, ptrdiff_t lds, float *dst) {
    int col = 0;
    for (; N - col >= 8 * VW; col += 8 * VW) {
        V c[8];
        for (int v = 0; v < 8; v++) c[v] = F(splat)(0.0f);
        for (ptrdiff_t i = 0; i < M; i++)
            for (int v = 0; v < 8; v++) c[v] += LD(src + i * lds + col + v * VW);
        for (int v = 0; v < 8; v++) ST(dst + col + v * VW, c[v]);
    }
    for (; N - col >= 4 * VW; col += 4 * VW) {
        V c0 = F(splat)(0.0f), c1 = c0, c2 = c0, c3 = c0;
        for (ptrdiff_t i = 0; i < M; i++) {
            const float *x = src + i * lds + col;
            c0 += LD(x); c1 += LD(x + VW); c2 += LD(x + 2 * VW); c3 += LD(x + 3 * VW);
        }
        ST(dst + col, c0); ST(dst + col + VW, c1);
        ST(dst + col + 2 * VW, c2); ST(dst + col + 3 * VW, c3);
    }
    for (; col < N; col += VW) {
        V c0 = F(splat)(0.0f);
        for (ptrdiff_t i = 0; i < M; i++) c0 += LD(src + i * lds + col);
        ST(dst + col, c0);
    }
}

/* out[q] = sum over h < n of x_q[h] y_q[h] for 8 pairs of rows at once, h in
 * ascending order (8 independent sums, so the adds overlap), each step one
 * fmaf. */
INL void F(dot8)(int n, const float *const x[8], const float *const y[8], float out[8]) {
    float c0 = 0.0f, c1 = 0.0f, c2 = 0.0f, c3 = 0.0f, c4 = 0.0f, c5 = 0.0f, c6 = 0.0f,
          c7 = 0.0f;
    for (int h = 0; h < n; h++) {
        c0 = __builtin_fmaf(x[0][h], y[0][h], c0); c1 = __builtin_fmaf(x[1][h], y[1][h], c1);
        c2 = __builtin_fmaf(x[2][h], y[2][h], c2); c3 = __builtin_fmaf(x[3][h], y[3][h], c3);
        c4 = __builtin_fmaf(x[4][h], y[4][h], c4); c5 = __builtin_fmaf(x[5][h], y[5][h], c5);
        c6 = __builtin_fmaf(x[6][h], y[6][h], c6); c7 = __builtin_fmaf(x[7][h], y[7][h], c7);
    }
    out[0] = c0; out[1] = c1; out[2] = c2; out[3] = c3;
    out[4] = c4; out[5] = c5; out[6] = c6; out[7] = c7;
}

/* Adam on n parameters, the gradient scaled by `scale` (the clipping);
 * b1t, b2t: 0.9^t and 0.999^t (double products, no libm pow). Element-wise,
 * every operation rounded on its own. */
TARGET static void F(adam)(float *restrict p, const float *restrict g, float *restrict m,
                           float *restrict v, size_t n, double lr, double b1t, double b2t,
                           float scale) {
    const float b1 = 0.9f, b2 = 0.999f;
    const float step = (float)(lr * sqrt(1.0 - b2t) / (1.0 - b1t));
    for (size_t i = 0; i < n; i++) {
        float gi = g[i] * scale;
        m[i] = b1 * m[i] + (1.0f - b1) * gi;
        v[i] = b2 * v[i] + (1.0f - b2) * gi * gi;
        p[i] -= step * m[i] / (sqrtf(v[i]) + 1e-8f);
    }
}

/* The whole training, see iloci_rnnpb_train in _native.c for the arguments.
 * Returns 0, or 1 when out of memory. */
TARGET static int F(train)(iloci_rnnpb_train_args *a) {
    const int D = a->D, H = a->H, P = a->P, R = a->R, S = a->D + a->C;
    const int Sp = round16(S), Hp = round16(H), L = a->T - 1;
    const float alpha = a->alpha, bound = a->bound;
    const float *X = a->X, *mw = a->mw;
    /* flat padded parameters: Ws (Sp, Hp) | Wp (P, Hp) | bh (Hp) | Wo (Hp, Sp) | bo (Sp) */
    const size_t nWs = (size_t)Sp * Hp, nWp = (size_t)P * Hp, nWo = (size_t)Hp * Sp;
    const size_t nW = nWs + nWp + Hp + nWo + Sp, nU = (size_t)R * P;
    const size_t LR = (size_t)L * R;
    size_t total = 4 * nW + 4 * nU          /* params, grads, Adam m, v; u's grad, m, v, pb */
                   + LR * Hp * 2 + LR * Sp * 2   /* H, DZ, O, G */
                   + (alpha != 1.0f ? LR * Sp : 0) /* IN when teacher-forced in part */
                   + (size_t)R * Sp + (size_t)R * Hp * 2 + nWs + nWo + Sp;
    float *mem = zeroed_floats(total);
    if (!mem) return 1;
    /* every array a vector touches starts a multiple of 16 floats (64
       bytes) into mem: the PB's (R P floats each) come last */
    float *w = mem, *g = w + nW, *m = g + nW, *v = m + nW;
    float *Hs = v + nW, *DZ = Hs + LR * Hp, *Os = DZ + LR * Hp, *G = Os + LR * Sp;
    float *IN = alpha != 1.0f ? G + LR * Sp : NULL;
    float *s0 = (IN ? IN + LR * Sp : G + LR * Sp), *pre = s0 + (size_t)R * Sp;
    float *sdz = pre + (size_t)R * Hp, *WoT = sdz + (size_t)R * Hp, *WsTm = WoT + nWo;
    float *mix = WsTm + nWs;
    float *gu = mix + Sp, *mu = gu + nU, *vu = mu + nU, *pb = vu + nU;
    float *Ws = w, *Wp = Ws + nWs, *bh = Wp + nWp, *Wo = bh + Hp, *bo = Wo + nWo;
    float *gWs = g, *gWp = gWs + nWs, *gbh = gWp + nWp, *gWo = gbh + Hp, *gbo = gWo + nWo;
    float *u = a->u;

    pad_network(D, a->C, H, P, R, a->w_in, a->b_hidden, a->w_out, a->b_out, X, w, s0);
    for (int j = 0; j < S; j++) mix[j] = j < D ? alpha : 1.0f;

    float loss = 0.0f;
    double b1t = 1.0, b2t = 1.0;  /* 0.9^t, 0.999^t */
    int t = 1;
    for (; t <= a->epochs; t++) {
        /* PB = bound tanh(u); pre = PB @ Wp + bh: the same every step */
        for (size_t i = 0; i < nU; i++) pb[i] = bound * F(stanh)(u[i]);
        for (int r = 0; r < R; r++)
            for (int h = 0; h < Hp; h += VW) {
                V acc = LD(bh + h);
                for (int k = 0; k < P; k++)
                    acc = F(vfma)(F(splat)(pb[r * P + k]), LD(Wp + k * Hp + h), acc);
                ST(pre + r * Hp + h, acc);
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
            /* the sums run over the S state and H hidden units only: the
               padded ones are exactly zero (see the layout in _native.c) */
            F(gemm)(R, S, Hp, in, Sp, Ws, pre, Hp, 0, h, EPI_TANH, NULL);
            F(gemm)(R, H, Sp, h, Hp, Wo, bo, 0, 0, Os + (size_t)s * R * Sp, EPI_TANH, NULL);
        }
        /* loss = sum mw mean_D (y - x)^2; G = dL/do (whole rows: zero past D) */
        double lsum = 0.0;
        for (size_t i = 0; i < LR; i++) {
            const float *o = Os + i * Sp, *x = X + (i + R) * D;
            float wgt = mw[i], part = 0.0f;
            for (int j = 0; j < Sp; j += VW) ST(G + i * Sp + j, F(splat)(0.0f));
            for (int j = 0; j < D; j++) {
                float d = o[j] - x[j];
                part += d * d;
                G[i * Sp + j] = d * wgt * (2.0f / D);
            }
            lsum += (double)(part * wgt);
        }
        loss = (float)(lsum / D);
        if (a->loss_history) a->loss_history[t - 1] = loss;
        /* backward: go_t = (G_t + carry) (1 - o_t^2); dz_t = (go_t Wo^T) (1 - h_t^2);
           carry into G_{t-1} = dz_t (mix Ws)^T, since s_t holds o_{t-1} mix; the
           carry's product applies G_{t-1}'s (1 - o^2) as it stores it */
        for (int h = 0; h < Hp; h++)
            for (int j = 0; j < Sp; j++) {
                WoT[j * Hp + h] = Wo[h * Sp + j];
                WsTm[h * Sp + j] = Ws[j * Hp + h] * (j < S ? mix[j] : 0.0f);
            }
        for (int s = L - 1; s >= 0; s--) {
            float *go = G + (size_t)s * R * Sp;
            const float *o = Os + (size_t)s * R * Sp;
            if (s == L - 1)  /* no carry into the last step */
                for (int i = 0; i < R * Sp; i++) go[i] *= 1.0f - o[i] * o[i];
            float *dz = DZ + (size_t)s * R * Hp;
            F(gemm)(R, S, Hp, go, Sp, WoT, NULL, 0, 0, dz, EPI_DTANH, Hs + (size_t)s * R * Hp);
            if (s > 0) F(gemm)(R, H, Sp, dz, Hp, WsTm, NULL, 0, 1, go - (size_t)R * Sp,
                               EPI_DTANH, o - (size_t)R * Sp);
        }
        /* weight gradients: sums over all steps and rows, each part of g
           written whole (no zeroing pass) */
        F(gemm_tn)((int)LR, H, Sp, Hs, Hp, G, 0, gWo);
        F(gemm_tn)(R, S, Hp, s0, Sp, DZ, 0, gWs);
        if (L > 1)
            F(gemm_tn)((int)(LR - R), S, Hp, IN ? IN + (size_t)R * Sp : Os, Sp,
                       DZ + (size_t)R * Hp, 1, gWs);
        F(colsum)((ptrdiff_t)LR, Sp, G, Sp, gbo);
        /* sdz[r] = sum over steps of dz[., r]; gbh = sum over rows of sdz;
           gWp = PB^T sdz */
        F(colsum)(L, R * Hp, DZ, (ptrdiff_t)R * Hp, sdz);
        F(colsum)(R, Hp, sdz, Hp, gbh);
        for (int k = 0; k < P; k++)
            for (int h = 0; h < Hp; h += VW) {
                V acc = F(splat)(0.0f);
                for (int r = 0; r < R; r++)
                    acc = F(vfma)(F(splat)(pb[r * P + k]), LD(sdz + (size_t)r * Hp + h), acc);
                ST(gWp + (size_t)k * Hp + h, acc);
            }
        /* dL/du = (sdz Wp^T) bound (1 - tanh(u)^2), 8 of the R P sums at a time */
        for (int q0 = 0; q0 < R * P; q0 += 8) {
            const float *x[8], *y[8];
            float dots[8];
            for (int c = 0; c < 8; c++) {
                int q = q0 + c < R * P ? q0 + c : q0;  /* past the end: a copy, unused */
                x[c] = sdz + (size_t)(q / P) * Hp;
                y[c] = Wp + (size_t)(q % P) * Hp;
            }
            F(dot8)(Hp, x, y, dots);
            for (int c = 0; c < 8 && q0 + c < R * P; c++) {
                float th = F(stanh)(u[q0 + c]);
                gu[q0 + c] = dots[c] * bound * (1.0f - th * th);
            }
        }
        /* clip the weight gradient's global norm, then Adam; the squares
           summed in 8 interleaved partial sums (nW is a multiple of 16) */
        double sq8[8] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
        for (size_t i = 0; i < nW; i += 8)
            for (int k = 0; k < 8; k++) sq8[k] += (double)g[i + k] * g[i + k];
        double sq = ((sq8[0] + sq8[1]) + (sq8[2] + sq8[3]))
                    + ((sq8[4] + sq8[5]) + (sq8[6] + sq8[7]));
        double scale = a->clip / (sqrt(sq) + 1e-12);
        if (scale > 1.0) scale = 1.0;
        double f = schedule_decay(a, t);
        double ramp = a->warmup > 0 ? (t < a->warmup ? (double)t / a->warmup : 1.0) : 1.0;
        b1t *= 0.9;
        b2t *= 0.999;
        F(adam)(w, g, m, v, nW, a->lr * f * ramp, b1t, b2t, (float)scale);
        F(adam)(u, gu, mu, vu, nU, a->pb_lr * f, b1t, b2t, 1.0f);
    }
    a->epochs_run = t - 1;

    for (int j = 0; j < S; j++) {
        for (int h = 0; h < H; h++) a->w_in[j * H + h] = Ws[j * Hp + h];
        a->b_out[j] = bo[j];
    }
    for (int k = 0; k < P; k++)
        for (int h = 0; h < H; h++) a->w_in[(S + k) * H + h] = Wp[k * Hp + h];
    for (int h = 0; h < H; h++) {
        a->b_hidden[h] = bh[h];
        for (int j = 0; j < S; j++) a->w_out[h * S + j] = Wo[h * Sp + j];
    }
    a->loss = loss;
    free(mem);
    return 0;
}

/* Closed-loop residuals of every row under PB = bound tanh(u), and by
 * forward-mode differentiation along u's P coordinates each row's
 * Gauss-Newton system: e[r] = sum_{t,j} res^2, A[r] = J^T J (P x P), g[r] =
 * J^T res, res[t, r, j] = (o_t[j] - x_{t+1}[j]) sw[t, r], j < D. The P
 * derivative copies of the batch are carried through the steps as P blocks
 * of R rows (the torch path's residuals_and_jacobian, without storing J). */
TARGET static void F(lm_system)(lm_work *w, const float *u, double *e, double *A,
                                double *g) {
    const int D = w->D, P = w->P, R = w->R, L = w->L, Sp = w->Sp, Hp = w->Hp;
    const float bound = w->bound;
    for (int r = 0; r < R; r++) {
        e[r] = 0.0;
        for (int k = 0; k < P; k++) {
            g[r * P + k] = 0.0;
            for (int q = 0; q < P; q++) A[(r * P + k) * P + q] = 0.0;
        }
    }
    /* pre = PB @ Wp + bh; dpre[k, r] = bound (1 - tanh(u_rk)^2) Wp[k] */
    for (int r = 0; r < R; r++) {
        for (int h = 0; h < Hp; h++) w->pre[r * Hp + h] = w->bh[h];
        for (int k = 0; k < P; k++) {
            float th = F(stanh)(u[r * P + k]), pb = bound * th, dp = bound * (1.0f - th * th);
            for (int h = 0; h < Hp; h++) {  /* as training's pre: one fma per k */
                w->pre[r * Hp + h] = __builtin_fmaf(pb, w->Wp[k * Hp + h], w->pre[r * Hp + h]);
                w->dpre[((size_t)k * R + r) * Hp + h] = dp * w->Wp[k * Hp + h];
            }
        }
    }
    for (int t = 0; t < L; t++) {
        float *h = w->Hs + (size_t)t * R * Hp, *o = w->Os + (size_t)t * R * Sp;
        const float *in = t ? w->Os + (size_t)(t - 1) * R * Sp : w->s0;
        F(gemm)(R, Sp, Hp, in, Sp, w->Ws, w->pre, Hp, 0, h, EPI_TANH, NULL);
        F(gemm)(R, Hp, Sp, h, Hp, w->Wo, w->bo, 0, 0, o, EPI_TANH, NULL);
        for (int k = 0; k < P; k++) {
            float *dh = w->dh + (size_t)k * R * Hp, *dout = w->dout + (size_t)k * R * Sp;
            /* d s_0 / du = 0 (s_0 is the data); then s_t = o_{t-1} */
            F(gemm)(R, t ? Sp : 0, Hp, dout, Sp, w->Ws, w->dpre + (size_t)k * R * Hp, Hp, 0,
                    dh, EPI_DTANH, h);
            F(gemm)(R, Hp, Sp, dh, Hp, w->Wo, NULL, 0, 0, dout, EPI_DTANH, o);
        }
        const float *x = w->X + (size_t)(t + 1) * R * D, *sw = w->sw + (size_t)t * R;
        for (int r = 0; r < R; r++) {
            float jd[LM_P_MAX][WIDTH_MAX], res[WIDTH_MAX];
            for (int j = 0; j < D; j++) {
                res[j] = (o[r * Sp + j] - x[r * D + j]) * sw[r];
                e[r] += (double)res[j] * res[j];
                for (int k = 0; k < P; k++)
                    jd[k][j] = w->dout[((size_t)k * R + r) * Sp + j] * sw[r];
            }
            for (int k = 0; k < P; k++) {
                double gk = 0.0;
                for (int j = 0; j < D; j++) gk += (double)jd[k][j] * res[j];
                g[r * P + k] += gk;
                for (int q = 0; q <= k; q++) {
                    double a = 0.0;
                    for (int j = 0; j < D; j++) a += (double)jd[k][j] * jd[q][j];
                    A[(r * P + k) * P + q] += a;
                    if (q != k) A[(r * P + q) * P + k] += a;
                }
            }
        }
    }
}

/* Closed-loop prediction error of every row under its PB, the arithmetic of
 * training's forward pass: a->u holds the PBs themselves (R, P), a->sw the
 * mask (T - 1, R); err[r] = sum_t mask[t, r] sum_D (o - x)^2 / D /
 * max(1, sum_t mask[t, r]), the sums over t in float64. Returns 0, or 1 when
 * out of memory. */
TARGET static int F(errors)(iloci_rnnpb_recognize_args *a) {
    lm_work w;
    if (lm_work_init(&w, a)) return 1;
    const int D = a->D, P = a->P, R = a->R, L = a->T - 1, Sp = w.Sp, Hp = w.Hp;
    const int S = a->D + a->C, H = a->H;
    const float *pb = a->u;
    for (int r = 0; r < R; r++)
        for (int h = 0; h < Hp; h += VW) {
            V acc = LD(w.bh + h);
            for (int k = 0; k < P; k++)
                acc = F(vfma)(F(splat)(pb[r * P + k]), LD(w.Wp + k * Hp + h), acc);
            ST(w.pre + r * Hp + h, acc);
        }
    for (int r = 0; r < R; r++) { w.sys[r] = 0.0; w.sys[R + r] = 0.0; }
    for (int t = 0; t < L; t++) {
        float *h = w.Hs + (size_t)t * R * Hp, *o = w.Os + (size_t)t * R * Sp;
        const float *in = t ? w.Os + (size_t)(t - 1) * R * Sp : w.s0;
        F(gemm)(R, S, Hp, in, Sp, w.Ws, w.pre, Hp, 0, h, EPI_TANH, NULL);
        F(gemm)(R, H, Sp, h, Hp, w.Wo, w.bo, 0, 0, o, EPI_TANH, NULL);
        const float *x = a->X + (size_t)(t + 1) * R * D, *m = a->sw + (size_t)t * R;
        for (int r = 0; r < R; r++) {
            float part = 0.0f;
            for (int j = 0; j < D; j++) {
                float d = o[r * Sp + j] - x[r * D + j];
                part += d * d;
            }
            w.sys[r] += (double)part * m[r];
            w.sys[R + r] += m[r];
        }
    }
    for (int r = 0; r < R; r++)
        a->err[r] = (float)(w.sys[r] / D / (w.sys[R + r] > 1.0 ? w.sys[R + r] : 1.0));
    lm_work_free(&w);
    return 0;
}

/* Levenberg-Marquardt on each row's u, the weights frozen: see
 * iloci_rnnpb_recognize in _native.c. Returns 0, or 1 when out of memory. */
TARGET static int F(recognize)(iloci_rnnpb_recognize_args *a) {
    lm_work w;
    if (lm_work_init(&w, a)) return 1;
    const int R = a->R, P = a->P;
    double *e = w.sys, *A = e + R, *g = A + (size_t)R * P * P;
    double *e2 = g + (size_t)R * P, *A2 = e2 + R, *g2 = A2 + (size_t)R * P * P;
    double *lam = g2 + (size_t)R * P;
    float *trial = w.trial;
    F(lm_system)(&w, a->u, e, A, g);
    for (int r = 0; r < R; r++) lam[r] = a->damping;
    for (int step = 0; step < a->steps; step++) {
        for (int r = 0; r < R; r++) {
            double M[LM_P_MAX][LM_P_MAX], delta[LM_P_MAX];
            const double *Ar = A + (size_t)r * P * P, *gr = g + (size_t)r * P;
            for (int k = 0; k < P; k++) {
                for (int q = 0; q < P; q++) M[k][q] = Ar[k * P + q];
                M[k][k] += lam[r] * (Ar[k * P + k] + a->tiny);
            }
            int ok = solve_spd(P, M, gr, delta);
            for (int k = 0; k < P; k++) {
                double v = ok ? a->u[r * P + k] - delta[k] : NAN;
                trial[r * P + k] = (float)(v < -a->u_max ? -a->u_max
                                           : v > a->u_max ? a->u_max : v);
            }
        }
        F(lm_system)(&w, trial, e2, A2, g2);
        for (int r = 0; r < R; r++) {
            /* false for NaN: a bad step is never kept */
            int better = e2[r] < e[r] && isfinite(trial[r * P]);
            for (int k = 0; k < P && better; k++) better = isfinite(trial[r * P + k]);
            if (better) {
                e[r] = e2[r];
                for (int k = 0; k < P; k++) {
                    a->u[r * P + k] = trial[r * P + k];
                    g[r * P + k] = g2[r * P + k];
                    for (int q = 0; q < P; q++)
                        A[((size_t)r * P + k) * P + q] = A2[((size_t)r * P + k) * P + q];
                }
            }
            lam[r] *= better ? a->down : a->up;
            lam[r] = lam[r] < a->lam_min ? a->lam_min : lam[r] > a->lam_max ? a->lam_max : lam[r];
        }
    }
    if (a->err)
        for (int r = 0; r < R; r++) a->err[r] = (float)e[r];
    lm_work_free(&w);
    return 0;
}

#undef V
#undef VU
#undef VI
#undef LD
#undef ST
#undef INL
#undef GEMM_TILE
#undef GEMM_TN_TILE
#undef F
#undef CAT
#undef CAT_
#undef FIRST_
#undef SECOND_
#undef FIRST
#undef SECOND
#undef GEMM_NB
#undef GEMM_ROWS
#undef TN_NB
#undef TN_ROWS
/* the parameters, so the next inclusion sets its own */
#undef VW
#undef SUFFIX
#undef TARGET
#undef VFMA
#undef WIDE
#undef VMIN
#undef VMAX
#undef SET1
#undef K_UNROLL
#undef GEMM_NB_ROWS
#undef TN_NB_ROWS
#undef TN_CHUNK
