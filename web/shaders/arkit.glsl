// ARKit's 52 blendshapes as morph targets (issue 16; retarget/arkit/shapes.py makes them,
// `ArkitShapes.posed` is the CPU twin):
//
//     v = v0 + sum_k w[k] * target[k, v]
//
// the painted fixes already multiplied into the targets (ArkitMorphs). ARKIT_TARGETS
// (defined by SkinnedFace.setArkit) is the shape count, 52; without it a face has no
// shapes and this chunk is empty. Needs skinning.glsl and morph_targets.glsl first.

#if defined( ARKIT_TARGETS )

	uniform bool arkitDrive; // the shapes pose the face, not the feature points' skinning
	uniform highp sampler2D arkitTargetTexture;
	uniform float arkitWeights[ ARKIT_TARGETS ];

	// Position of vertex `vertex` at rest position `rest`, posed by the 52 weights.
	vec3 arkitPosition( const in int vertex, const in vec3 rest ) {

		vec3 morphed = rest;
		MORPH_TARGETS_ADD( morphed, arkitTargetTexture, arkitWeights, ARKIT_TARGETS, vertex )
		return morphed;

	}

#endif
