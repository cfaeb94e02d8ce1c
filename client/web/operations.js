// The page's operations: each one's endpoint, what it is said to do, how its boxes and result
// are named, and what the result panel shows of it.

/**
 * By the value of its radio: ``path`` (the endpoint), ``hint`` (under the radios), and as
 * needed ``textureLabel`` (the texture box's label), ``targetHint``, ``several`` (it quilts
 * several textures together), ``direct`` (answered at once, not run as a job: no seed to
 * vary), ``input``/``result`` (the captions beside the result), ``presetsFrom`` (what the
 * block presets are a fraction of), ``view`` (the result view it opens in), ``download`` (the
 * result link's text), ``noSeams`` (why there are no seams to show), ``companions`` (labels of
 * the companion maps it returns) and ``wang`` (its result is a Wang tile set).
 */
export const OPERATIONS = {
  synthesize: {
    path: "/synthesize",
    hint: "A larger texture of any size from the sample, or from several quilted together.",
    textureLabel: "Texture",
    several: true,
  },
  transfer: {
    path: "/transfer",
    hint: "The target image rendered in the texture (texture transfer).",
    textureLabel: "Texture",
  },
  tile: {
    path: "/tile",
    hint: "The image itself, made to repeat seamlessly (same size, its centre kept).",
    textureLabel: "Image",
    direct: true, // answered with the image itself, not run as a job
  },
  matte: {
    path: "/matte",
    hint: "Textures laid on the surface of an object in the target image, following its " +
      "shape and shading (texture matting). The silhouette says where the surface is.",
    targetHint: "The picture of the object; the output has its size.",
    input: "Target",
    presetsFrom: "the first layer",
    noSeams: "A matting result has no block seams: each layer is quilted on its own, then " +
      "laid on the surface. The clusters download shows its patches.",
    companions: {
      normals: "normals (the estimated normal map)",
      clusters: "clusters (the patches in colours)",
    },
  },
  fill: {
    path: "/fill",
    hint: "What the mask marks (a stain, a logo, a cable) filled from the rest of the image; " +
      "every other pixel is kept as it is. Paint the mask on the image or choose one.",
    textureLabel: "Image",
    presetsFrom: "this image",
    input: "Before",
    result: "After",
    view: "side",
    noSeams: "A fill has no block seams to show: compare it with the image side by side.",
  },
  extend: {
    path: "/extend",
    hint: "The image grown past its borders (uncrop): the pixels added on each side " +
      "synthesized from the image, the image itself kept as it is.",
    textureLabel: "Image",
    presetsFrom: "this image",
    input: "Before",
    result: "After",
    view: "side",
    noSeams: "An extended image has no block seams to show: compare it with the image side " +
      "by side.",
  },
  wang: {
    path: "/wang-tiles",
    hint: "A set of Wang tiles quilted from the texture (or several): a tile for every " +
      "combination of edge colours, so that tiles whose edges share a colour join " +
      "seamlessly and lay out in endless arrangements that never repeat (Cohen et al. 2003). " +
      "The result is the atlas of the tiles, its manifest and a 6 × 6 preview.",
    textureLabel: "Texture",
    several: true,
    result: "Atlas",
    download: "Download atlas PNG",
    view: "single",
    noSeams: "A Wang tile set's atlas has no seams to show: see the tiles laid out in the " +
      "preview below.",
    wang: true,
  },
};
