// Per request, an upper bound U on the k-th smallest cost of its field: the exact k-th
// smallest of the run minima written by cost_field.comp (k runs each hold a cost <= U), or
// +inf when fewer than k minima are finite (then the whole field is listed).
//
// Radix select on the bit patterns (non-negative floats order like their uint bits): four
// passes of 8 bits from the top, each a 256-bin histogram in shared memory of the minima
// whose higher bits equal the prefix chosen so far; the bin where the running count reaches
// the remaining rank fixes the next 8 bits. Four reads of the minima instead of the 31 of a
// bisection, and the same answer bit for bit: min(k-th smallest bits, +inf), 0 for k = 0.
// One work group per request.
//
// Injected by quilting/costs/gl.py: LOCAL_X (any size: every loop strides by it) and the
// BINDING_<BUFFER> slots.

layout(local_size_x = LOCAL_X, local_size_y = 1, local_size_z = 1) in;

layout(std430, binding = BINDING_MINIMA) readonly buffer Minima { float minima[]; };  // n x count
#include "header.glsl"

uniform int count;  // run minima per request
uniform uint k;     // min_candidates

#define BINS 256u
#define GROUPS 16u  // the bins are scanned in GROUPS groups of BINS / GROUPS

shared uint hist[BINS];
shared uint part[GROUPS];
shared uint chosen;     // the bits fixed so far
shared uint remaining;  // the rank still to find among the minima that share them
shared bool found;

const uint INF = 0x7F800000u;

void main() {
    uint lid = gl_LocalInvocationIndex;
    int r_index = int(gl_WorkGroupID.x);
    int base = r_index * count;
    if (k == 0u) {  // as the bisection: every value has at least 0 minima below it
        if (lid == 0u) {
            upper[r_index] = 0.0;
        }
        return;
    }
    uint prefix = 0u;
    uint rank = k;
    bool ok = true;
    for (int level = 0; level < 4; ++level) {
        int shift = 24 - 8 * level;
        // The bits above this pass's byte must equal the prefix (none in the first pass).
        uint high = level == 0 ? 0u : ~((1u << uint(shift + 8)) - 1u);
        for (uint i = lid; i < BINS; i += LOCAL_X) {
            hist[i] = 0u;
        }
        barrier();
        // Neighbouring minima are close, so most fall into the same bin as the previous one
        // read: count those in a register and add them once (fewer contended atomics).
        uint run_bin = BINS;
        uint run_n = 0u;
        for (int i = int(lid); i < count; i += LOCAL_X) {
            uint key = floatBitsToUint(minima[base + i]);
            if (((key ^ prefix) & high) != 0u) {
                continue;
            }
            uint bin = (key >> uint(shift)) & 0xFFu;
            if (bin != run_bin) {
                if (run_n > 0u) {
                    atomicAdd(hist[run_bin], run_n);
                }
                run_bin = bin;
                run_n = 0u;
            }
            run_n += 1u;
        }
        if (run_n > 0u) {
            atomicAdd(hist[run_bin], run_n);
        }
        barrier();
        for (uint g = lid; g < GROUPS; g += LOCAL_X) {
            uint sum = 0u;
            for (uint b = g * (BINS / GROUPS); b < (g + 1u) * (BINS / GROUPS); ++b) {
                sum += hist[b];
            }
            part[g] = sum;
        }
        barrier();
        if (lid == 0u) {
            uint r = rank;
            uint g = 0u;
            while (g < GROUPS && part[g] < r) {
                r -= part[g];
                ++g;
            }
            found = g < GROUPS;  // false only in the first pass: fewer than k minima at all
            if (found) {
                uint b = g * (BINS / GROUPS);
                while (hist[b] < r) {  // ends in this group: its sum is >= r
                    r -= hist[b];
                    ++b;
                }
                chosen = prefix | (b << uint(shift));
                remaining = r;
            }
        }
        barrier();
        ok = found;
        prefix = chosen;
        rank = remaining;
        // The next pass writes chosen, remaining and found only after three more barriers.
        if (!ok) {
            break;  // uniform: every invocation read the same flag
        }
    }
    if (lid == 0u) {
        upper[r_index] = uintBitsToFloat(ok ? min(prefix, INF) : INF);
    }
}
