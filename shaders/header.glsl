// The selection kernels' shared header: written by kth_bound.comp and shortlist.comp.
layout(std430, binding = BINDING_HEADER) buffer Header {
    uint total;      // shortlist entries appended by shortlist.comp
    uint pad0, pad1, pad2;
    float upper[];   // U per request, from kth_bound.comp
};
