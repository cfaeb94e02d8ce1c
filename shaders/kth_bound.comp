// Per request, an upper bound U on the k-th smallest cost of its field: the exact k-th
// smallest of the run minima written by cost_field.comp (k runs each hold a cost <= U).
// Found by bisection on the bit patterns (non-negative floats order like their bits): each
// step counts the minima <= the midpoint across the work group. One work group per request.
//
// Injected by quilting/costs/gl.py: LOCAL_X and the BINDING_<BUFFER> slots.

layout(local_size_x = LOCAL_X, local_size_y = 1, local_size_z = 1) in;

layout(std430, binding = BINDING_MINIMA) readonly buffer Minima { float minima[]; };  // n x count
#include "header.glsl"

uniform int count;  // run minima per request
uniform uint k;     // min_candidates

shared uint below;

void main() {
    int r_index = int(gl_WorkGroupID.x);
    int base = r_index * count;
    uint lo = 0u;
    uint hi = 0x7F800000u;  // +inf: fewer than k finite minima leaves U infinite
    // Invariant: at least k minima are <= hi (or hi is +inf); none of the answers is < lo.
    while (lo < hi) {
        uint mid = lo + (hi - lo) / 2u;
        if (gl_LocalInvocationIndex == 0u) {
            below = 0u;
        }
        barrier();
        uint mine = 0u;
        for (int i = int(gl_LocalInvocationIndex); i < count; i += LOCAL_X) {
            mine += floatBitsToUint(minima[base + i]) <= mid ? 1u : 0u;
        }
        atomicAdd(below, mine);
        barrier();
        uint seen = below;
        barrier();
        if (seen >= k) {
            hi = mid;
        } else {
            lo = mid + 1u;
        }
    }
    if (gl_LocalInvocationIndex == 0u) {
        upper[r_index] = uintBitsToFloat(hi);
    }
}
