// Cost field of a batch of blocks: for every request and every candidate position (y, x) of
// the source, the cost
//   sum_mask M (S - T)^2  +  w_prev sum_block (S - P)^2  +  w_guide sum_block (G_S - G)^2
// by direct summation in float32 (the engine re-scores near-ties exactly in float64).
//
// Dispatch: x = runs of RUN consecutive candidates of one field row, y = field row,
// z = request. Each invocation keeps RUN accumulators and a sliding window of RUN source
// pixels in registers: one new source pixel per template pixel, reused by RUN candidates.
// Besides the field it writes the minimum of its run, which the selection kernel reduces.
//
// Injected by quilting/costs/gl.py: BLOCK, CHANNELS (1, 3, 4), GUIDE_CHANNELS (0 = no guide
// term), HAS_PREVIOUS (0, 1), RUN, LOCAL_X, LOCAL_Y, and the BINDING_<BUFFER> slots.

layout(local_size_x = LOCAL_X, local_size_y = LOCAL_Y, local_size_z = 1) in;

#if CHANNELS == 1
#define PIXEL float
#elif CHANNELS == 3
#define PIXEL vec3
#else
#define PIXEL vec4
#endif

#define FULL_BLOCK (HAS_PREVIOUS == 1 || GUIDE_CHANNELS > 0)

#include "request.glsl"

layout(std430, binding = BINDING_SOURCE) readonly buffer Source { float src[]; };  // H x W x C
layout(std430, binding = BINDING_TEMPLATES) readonly buffer Templates { float tmpl[]; };  // n x B x B x C
layout(std430, binding = BINDING_MASKS) readonly buffer Masks { float mask[]; };  // m x B x B
layout(std430, binding = BINDING_SPANS) readonly buffer Spans { ivec2 span[]; };  // m x B: [c0, c1)
layout(std430, binding = BINDING_REQUESTS) readonly buffer Requests { Request req[]; };
layout(std430, binding = BINDING_FIELD) writeonly buffer Field { float field[]; };  // n x fh x fw
layout(std430, binding = BINDING_MINIMA) writeonly buffer Minima { float minima[]; };  // n x fh x gw
#if HAS_PREVIOUS == 1
layout(std430, binding = BINDING_PREVIOUS) readonly buffer Previous { float prev[]; };  // n x B x B x C
#endif
#if GUIDE_CHANNELS > 0
layout(std430, binding = BINDING_GUIDE) readonly buffer GuideSource { float gsrc[]; };  // H x W x K
layout(std430, binding = BINDING_GUIDES) readonly buffer Guides { float gtmpl[]; };  // n x B x B x K
#endif

uniform int src_w;
uniform int field_w;
uniform int field_h;
uniform int groups_w;

PIXEL load(int pixel) {
#if CHANNELS == 1
    return src[pixel];
#elif CHANNELS == 3
    int i = pixel * 3;
    return vec3(src[i], src[i + 1], src[i + 2]);
#else
    int i = pixel * 4;
    return vec4(src[i], src[i + 1], src[i + 2], src[i + 3]);
#endif
}

PIXEL load_template(int pixel) {
#if CHANNELS == 1
    return tmpl[pixel];
#elif CHANNELS == 3
    int i = pixel * 3;
    return vec3(tmpl[i], tmpl[i + 1], tmpl[i + 2]);
#else
    int i = pixel * 4;
    return vec4(tmpl[i], tmpl[i + 1], tmpl[i + 2], tmpl[i + 3]);
#endif
}

#if HAS_PREVIOUS == 1
PIXEL load_previous(int pixel) {
#if CHANNELS == 1
    return prev[pixel];
#elif CHANNELS == 3
    int i = pixel * 3;
    return vec3(prev[i], prev[i + 1], prev[i + 2]);
#else
    int i = pixel * 4;
    return vec4(prev[i], prev[i + 1], prev[i + 2], prev[i + 3]);
#endif
}
#endif

float sq(float d) { return d * d; }
float sq(vec2 d) { return dot(d, d); }
float sq(vec3 d) { return dot(d, d); }
float sq(vec4 d) { return dot(d, d); }

void main() {
    int run = int(gl_GlobalInvocationID.x);
    int y = int(gl_GlobalInvocationID.y);
    int r_index = int(gl_GlobalInvocationID.z);
    if (run >= groups_w || y >= field_h) {
        return;
    }
    int x0 = run * RUN;
    Request q = req[r_index];
    int m = q.mask;
    int last = src_w - 1;  // window reads past the last candidate are clamped, then unused
    int block_px = BLOCK * BLOCK;

    float acc[RUN];
    for (int i = 0; i < RUN; ++i) {
        acc[i] = 0.0;
    }
    PIXEL win[RUN];

    for (int r = 0; r < BLOCK; ++r) {
#if FULL_BLOCK
        int c0 = 0;
        int c1 = BLOCK;
#else
        ivec2 s = span[m * BLOCK + r];
        int c0 = s.x;
        int c1 = s.y;
        if (c0 >= c1) {
            continue;
        }
#endif
        int row = (y + r) * src_w;
        for (int i = 0; i < RUN; ++i) {
            win[i] = load(row + min(x0 + c0 + i, last));
        }
        int tbase = r_index * block_px + r * BLOCK;
        int mbase = m * block_px + r * BLOCK;
        for (int c = c0; c < c1; ++c) {
            PIXEL t = load_template(tbase + c);
            float w = mask[mbase + c];
#if HAS_PREVIOUS == 1
            PIXEL p = load_previous(tbase + c);
            float wp = q.w_prev;
#endif
            for (int i = 0; i < RUN; ++i) {
                acc[i] += w * sq(win[i] - t);
#if HAS_PREVIOUS == 1
                acc[i] += wp * sq(win[i] - p);
#endif
            }
            for (int i = 0; i < RUN - 1; ++i) {
                win[i] = win[i + 1];
            }
            win[RUN - 1] = load(row + min(x0 + c + RUN, last));
        }
    }

#if GUIDE_CHANNELS > 0
    // The correspondence term over the whole block, against the source's guide map.
    float gwin[RUN * GUIDE_CHANNELS];
    float wg = q.w_guide;
    for (int r = 0; r < BLOCK; ++r) {
        int row = (y + r) * src_w;
        for (int i = 0; i < RUN; ++i) {
            int px = (row + min(x0 + i, last)) * GUIDE_CHANNELS;
            for (int k = 0; k < GUIDE_CHANNELS; ++k) {
                gwin[i * GUIDE_CHANNELS + k] = gsrc[px + k];
            }
        }
        int tbase = (r_index * block_px + r * BLOCK) * GUIDE_CHANNELS;
        for (int c = 0; c < BLOCK; ++c) {
            for (int i = 0; i < RUN; ++i) {
                float e = 0.0;
                for (int k = 0; k < GUIDE_CHANNELS; ++k) {
                    float d = gwin[i * GUIDE_CHANNELS + k] - gtmpl[tbase + c * GUIDE_CHANNELS + k];
                    e += d * d;
                }
                acc[i] += wg * e;
            }
            for (int i = 0; i < (RUN - 1) * GUIDE_CHANNELS; ++i) {
                gwin[i] = gwin[i + GUIDE_CHANNELS];
            }
            int px = (row + min(x0 + c + RUN, last)) * GUIDE_CHANNELS;
            for (int k = 0; k < GUIDE_CHANNELS; ++k) {
                gwin[(RUN - 1) * GUIDE_CHANNELS + k] = gsrc[px + k];
            }
        }
    }
#endif

    int out_row = (r_index * field_h + y) * field_w;
    float best = uintBitsToFloat(0x7F800000u);  // +inf
    for (int i = 0; i < RUN; ++i) {
        if (x0 + i < field_w) {
            field[out_row + x0 + i] = acc[i];
            best = min(best, acc[i]);
        }
    }
    minima[(r_index * field_h + y) * groups_w + run] = best;
}
