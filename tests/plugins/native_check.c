/*
 * A fixed batch through the native kernel, every result printed as the bits
 * of its float32s: the harness of tests/plugins/test_native_aarch64.py,
 * compiled for this machine and cross-compiled for aarch64 (run under
 * qemu-user), so the two outputs can be compared bit for bit.
 *
 *   native_check ISA     ISA: 1 portable, 2 AVX2, 3 AVX-512 (x86-64 only)
 *
 * The data and the initial weights come from integer arithmetic only (no
 * libm), so both machines start from the same bits. Prints one line per
 * array: its name and its values as 8 hex digits each; exits 1 when the
 * kernel refuses.
 */
#define ILOCI_NATIVE_NO_PYTHON 1
#include "../../plugins/iloci-native/iloci_native/_native.c"

#include <stdio.h>

enum { T = 20, R = 5, D = 6, C = 10, H = 24, P = 3, S = D + C };

static uint32_t state = 12345u;
static float uniform(float scale) {   /* [-scale, scale), exact in float32 */
    state = state * 1664525u + 1013904223u;
    return ((float)(state >> 8) * (1.0f / 16777216.0f) * 2.0f - 1.0f) * scale;
}

static void print(const char *name, const float *a, size_t n) {
    printf("%s", name);
    for (size_t i = 0; i < n; i++) {
        uint32_t bits;
        memcpy(&bits, &a[i], 4);
        printf(" %08x", bits);
    }
    printf("\n");
}

int main(int argc, char **argv) {
    int isa = argc > 1 ? atoi(argv[1]) : ISA_PORTABLE;
    static float X[T * R * D], mw[(T - 1) * R], sw[(T - 1) * R], mask[(T - 1) * R];
    static float w_in[(S + P) * H], b_hidden[H], w_out[H * S], b_out[S], u[R * P];
    static float hist[300], err[R], pbs[R * P];
    for (int r = 0; r < R; r++)
        for (int j = 0; j < D; j++) {
            float x = uniform(0.5f);
            for (int t = 0; t < T; t++) {
                x += uniform(0.05f);
                X[(t * R + r) * D + j] = x;
            }
        }
    for (int t = 0; t < T - 1; t++)
        for (int r = 0; r < R; r++) {
            float m = t < T - 1 - r ? 1.0f : 0.0f;   /* rows of different lengths */
            mask[t * R + r] = m;
            mw[t * R + r] = m / (float)((T - 1 - r) * R);
            sw[t * R + r] = m;
        }
    for (int i = 0; i < (S + P) * H; i++) w_in[i] = uniform(0.3f);
    for (int i = 0; i < H * S; i++) w_out[i] = uniform(0.3f);
    for (int i = 0; i < R * P; i++) u[i] = uniform(0.5f);

    iloci_rnnpb_train_args a = {0};
    a.size = sizeof a; a.isa = isa; a.epochs = 300; a.T = T; a.R = R; a.D = D; a.C = C;
    a.H = H; a.P = P; a.warmup = 20; a.alpha = 0.5f; a.bound = 1.0f; a.lr = 0.01;
    a.pb_lr = 0.05; a.decay = 0.3; a.clip = 0.5; a.X = X; a.mw = mw; a.w_in = w_in;
    a.b_hidden = b_hidden; a.w_out = w_out; a.b_out = b_out; a.u = u; a.loss_history = hist;
    if (iloci_rnnpb_train(&a) != 0) return 1;
    print("w_in", w_in, sizeof w_in / 4);
    print("b_hidden", b_hidden, H);
    print("w_out", w_out, sizeof w_out / 4);
    print("b_out", b_out, S);
    print("u", u, R * P);
    print("loss_history", hist, 300);

    iloci_rnnpb_recognize_args g = {0};
    g.size = sizeof g; g.isa = isa; g.steps = 8; g.T = T; g.R = R; g.D = D; g.C = C;
    g.H = H; g.P = P; g.bound = 1.0f; g.damping = 1e-2; g.down = 0.3; g.up = 4.0;
    g.lam_min = 1e-9; g.lam_max = 1e9; g.tiny = 1e-12; g.u_max = 3.8; g.X = X; g.sw = sw;
    g.w_in = w_in; g.b_hidden = b_hidden; g.w_out = w_out; g.b_out = b_out;
    for (int i = 0; i < R * P; i++) u[i] = uniform(0.5f);
    g.u = u; g.err = err;
    if (iloci_rnnpb_recognize(&g) != 0) return 1;
    print("recognized_u", u, R * P);
    print("recognized_err", err, R);

    for (int i = 0; i < R * P; i++) pbs[i] = uniform(0.9f);
    g.u = pbs; g.sw = mask;
    if (iloci_rnnpb_errors(&g) != 0) return 1;
    print("scores", err, R);
    return 0;
}
