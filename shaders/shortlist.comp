// The shortlist: every candidate whose cost is <= (1 + tol)(U + b) + b, with U the bound from
// kth_bound.comp and b = rel * (1 + tol) * U + abs the request's error bound, appended to one
// list as (request * field_size + flat index, cost bits). The order of the entries is not
// deterministic; the host sorts them. Entries past the capacity are counted, not written: the
// host then reads the dense field instead.
//
// Dispatch: x and y = flat field index, z = request. Injected by quilting/costs/gl.py: LOCAL_X
// and the BINDING_<BUFFER> slots.

layout(local_size_x = LOCAL_X, local_size_y = 1, local_size_z = 1) in;

#include "request.glsl"

layout(std430, binding = BINDING_REQUESTS) readonly buffer Requests { Request req[]; };
layout(std430, binding = BINDING_FIELD) readonly buffer Field { float field[]; };  // n x field_size
#include "header.glsl"
layout(std430, binding = BINDING_ENTRIES) writeonly buffer Entries { uvec2 entries[]; };

uniform int field_size;
uniform uint capacity;
uniform float scale;  // 1 + tolerance

void main() {
    // Large fields spread over y too (work-group counts are limited per dimension).
    int index = int(gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x
                    + gl_GlobalInvocationID.x);
    int r_index = int(gl_GlobalInvocationID.z);
    if (index >= field_size) {
        return;
    }
    float u = upper[r_index];
    Request q = req[r_index];
    float b = q.rel * scale * u + q.abs_bound;
    // Inflated far past float32 rounding, so the list is complete for the host's bound.
    float threshold = (scale * (u + b) + b) * 1.00001;
    float value = field[r_index * field_size + index];
    if (value <= threshold) {
        uint slot = atomicAdd(total, 1u);
        if (slot < capacity) {
            entries[slot] = uvec2(uint(r_index * field_size + index), floatBitsToUint(value));
        }
    }
}
