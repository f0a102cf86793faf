// Display pass of SkinnedFace: a matte skin-like surface lit by the scene's lights (the
// Viewer's hemisphere, key, fill and rim), its albedo the scan's base-colour texture or a
// plain skin tone, or coloured by one joint's weights (heat map, over either).
// Lights follow three.js's conventions (ShaderMaterial with lights: true, Lambert / PI),
// so the face and any three.js material beside it answer the same lights the same way.

#include <common>
#include <lights_pars_begin>

uniform vec3 diffuse;      // albedo, linear
uniform float specular;    // reflectance at normal incidence (skin: about 0.03)
uniform float shininess;   // Blinn-Phong exponent
uniform int heatJoint;     // -1: off
uniform sampler2D baseColorMap; // sRGB texture, decoded to linear by the sampler
uniform bool textured;     // albedo from baseColorMap (else diffuse)

in vec3 vViewPosition;
in vec3 vNormal;
in float vHeat;
in vec2 vUv;

// three.js's output chunks below write gl_FragColor
layout( location = 0 ) out highp vec4 pc_fragColor;
#define gl_FragColor pc_fragColor

// Viridis for weights 0..1 (polynomial fit by Matt Zucker, CC0; sRGB), a red that viridis
// never uses for negative weights (dense deformers' undershoot, made visible from -0.001
// on), and a fade to white above 1 (overshoot).
vec3 heatColor( const in float w ) {

	const vec3 c0 = vec3( 0.2777273272234177, 0.005407344544966578, 0.3340998053353061 );
	const vec3 c1 = vec3( 0.1050930431085774, 1.404613529898575, 1.384590162594685 );
	const vec3 c2 = vec3( - 0.3308618287255563, 0.214847559468213, 0.09509516302823659 );
	const vec3 c3 = vec3( - 4.634230498983486, - 5.799100973351585, - 19.33244095627987 );
	const vec3 c4 = vec3( 6.228269936347081, 14.17993336680509, 56.69055260068105 );
	const vec3 c5 = vec3( 4.776384997670288, - 13.74514537774601, - 65.35303263337234 );
	const vec3 c6 = vec3( - 5.435455855934631, 4.645852612178535, 26.3124352495832 );

	float t = saturate( w );
	vec3 srgb = c0 + t * ( c1 + t * ( c2 + t * ( c3 + t * ( c4 + t * ( c5 + t * c6 ) ) ) ) );
	srgb = mix( srgb, vec3( 0.95, 0.16, 0.2 ), sqrt( saturate( - w / 0.05 ) ) );
	srgb = mix( srgb, vec3( 1.0 ), saturate( ( w - 1.0 ) / 0.25 ) );
	return sRGBTransferEOTF( vec4( saturate( srgb ), 1.0 ) ).rgb;

}

void main() {

	vec3 normal = normalize( vNormal ) * ( gl_FrontFacing ? 1.0 : - 1.0 );
	vec3 toEye = isOrthographic ? vec3( 0.0, 0.0, 1.0 ) : normalize( - vViewPosition );

	vec3 albedo = heatJoint >= 0 ? heatColor( vHeat ) : textured ? texture( baseColorMap, vUv ).rgb : diffuse;

	vec3 irradiance = getAmbientLightIrradiance( ambientLightColor );

	#if NUM_HEMI_LIGHTS > 0

		for ( int i = 0; i < NUM_HEMI_LIGHTS; i ++ ) irradiance += getHemisphereLightIrradiance( hemisphereLights[ i ], normal );

	#endif

	vec3 outgoing = irradiance * BRDF_Lambert( albedo );

	#if NUM_DIR_LIGHTS > 0

		for ( int i = 0; i < NUM_DIR_LIGHTS; i ++ ) {

			vec3 toLight = directionalLights[ i ].direction;
			float dotNL = saturate( dot( normal, toLight ) );
			vec3 halfway = normalize( toLight + toEye );
			float dotNH = saturate( dot( normal, halfway ) );
			float dotVH = saturate( dot( toEye, halfway ) );
			// normalised Blinn-Phong with Schlick's Fresnel: the sheen at grazing angles
			// outlines the face against the rim light
			float fresnel = specular + ( 1.0 - specular ) * pow( 1.0 - dotVH, 5.0 );
			float highlight = fresnel * ( shininess + 2.0 ) * ( 1.0 / 8.0 ) * pow( dotNH, shininess );
			outgoing += directionalLights[ i ].color * dotNL * ( BRDF_Lambert( albedo ) + RECIPROCAL_PI * highlight );

		}

	#endif

	gl_FragColor = vec4( outgoing, 1.0 );

	#include <tonemapping_fragment>
	#include <colorspace_fragment>

}
