// One cost request of a batch, as quilting/costs/gl.py stages it (8 x 4 bytes, std430).
struct Request {
    int mask;         // index into the masks and spans
    float w_prev;     // weight of the previous-pass term
    float w_guide;    // weight of the correspondence term
    float rel;        // relative error bound of this request's sums (selection kernels)
    float abs_bound;  // absolute part of that bound (flushed denormals)
    float pad0, pad1, pad2;
};
