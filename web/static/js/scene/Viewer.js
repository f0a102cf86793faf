import {
	Box3,
	Color,
	DirectionalLight,
	HemisphereLight,
	MathUtils,
	NeutralToneMapping,
	PerspectiveCamera,
	Scene,
	Sphere,
	SRGBColorSpace,
	Vector3,
	WebGLRenderer,
} from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

// Camera distance limits and clip planes, in bounding-sphere radii: meshes come in cm, m
// or mm, so no length here is absolute.
const NEAR = 0.01;
const FAR = 100;
const MIN_DISTANCE = 0.05;
const MAX_DISTANCE = 20;
const FRAME_MARGIN = 1.05;

/**
 * The 3D view: a WebGL2 renderer filling its container, a perspective camera with orbit
 * controls and lights that read facial detail, drawn on demand.
 *
 * A frame is drawn only after something visible changed: the camera (orbit controls,
 * framing, resize), the displayed object, or a scene object that says so with
 * `redraw( object )`. An idle view then costs nothing, where a loop drawing every
 * animation frame keeps a core busy under software WebGL (and a laptop's GPU awake).
 *
 * The lights ride with the camera (a studio rig around the viewer, not around the face),
 * so a face seen from any side is lit the same way: a cool hemisphere for soft fill from
 * above, a warm key from the upper left, a weak fill from the right and a rim from behind
 * that outlines the profile. Neutral tone mapping keeps the heat map's colours.
 */
export class Viewer {

	/**
	 * @param {HTMLElement} container - filled by the canvas; the view follows its size.
	 */
	constructor( container ) {

		this.container = container;

		try {

			this.renderer = new WebGLRenderer( { antialias: true } );

		} catch ( error ) {

			throw new Error( `Viewer: WebGL2 is not available in this browser (${ error.message }).`, { cause: error } );

		}

		this.renderer.setPixelRatio( window.devicePixelRatio );
		this.renderer.outputColorSpace = SRGBColorSpace;
		this.renderer.toneMapping = NeutralToneMapping;
		const canvas = this.renderer.domElement;
		canvas.style.display = 'block';
		canvas.style.width = '100%';
		canvas.style.height = '100%';
		canvas.style.touchAction = 'none';
		container.appendChild( canvas );

		this.scene = new Scene();
		this.scene.background = new Color( 0x1d1f23 );

		// a portrait lens: little perspective distortion, and from the front the camera still
		// sees the jaw line's sides, where contour landmarks go (at 30 degrees the cheeks hide them)
		this.camera = new PerspectiveCamera( 20, 1, NEAR, FAR );
		this.camera.position.set( 0, 0, 4 );
		this.scene.add( this.camera ); // its lights are its children

		this.scene.add( new HemisphereLight( 0xe4ecff, 0x40342e, 1.6 ) );
		// camera space: +z towards the viewer, +y up; a directional light shines from its
		// position towards its target, both children of the camera
		for ( const [ color, intensity, x, y, z ] of [
			[ 0xfff1e4, 2.6, - 1, 1, 1.2 ], // key
			[ 0xe8f0ff, 0.7, 1.2, - 0.1, 0.8 ], // fill
			[ 0xffffff, 1.8, 0.4, 0.9, - 1.2 ], // rim
		] ) {

			const light = new DirectionalLight( color, intensity );
			light.position.set( x, y, z );
			light.target.position.set( 0, 0, 0 );
			this.camera.add( light, light.target );

		}

		this.controls = new OrbitControls( this.camera, canvas );
		this.controls.enableDamping = true;
		this.controls.zoomToCursor = true;
		this.controls.addEventListener( 'change', () => this.invalidate() );
		this.scene.addEventListener( 'change', () => this.invalidate() );

		/** The displayed object (null: none). */
		this.object = null;
		this.wireframe = false;
		this._bounds = new Sphere( new Vector3(), 1 );
		this._frameRequest = null; // the pending requestAnimationFrame id
		this._width = this._height = 0; // container size, CSS pixels

		this._resizeObserver = new ResizeObserver( () => this._resize() );
		this._resizeObserver.observe( container );
		this._resize();

	}

	/**
	 * Show `object` instead of the current one and frame the camera on it.
	 * @param {import('three').Object3D|null} object
	 */
	setObject( object ) {

		if ( this.object !== null ) this.scene.remove( this.object );
		this.object = object;
		this.invalidate();
		if ( object !== null ) {

			this.scene.add( object );
			this.setWireframe( this.wireframe );
			this.frame();

		}

	}

	/**
	 * Fit the camera to the current object, seen from the front (the face looks down +z,
	 * +y is up), at the distance where its bounding sphere fills the narrower field of view.
	 */
	frame() {

		this._resize( false );
		if ( this.object !== null ) {

			this.object.updateMatrixWorld( true );
			const box = new Box3().setFromObject( this.object );
			if ( ! box.isEmpty() ) box.getBoundingSphere( this._bounds );

		}

		const { center } = this._bounds;
		const radius = Math.max( this._bounds.radius, Number.MIN_VALUE );
		const camera = this.camera;
		const halfFov = MathUtils.degToRad( camera.fov ) / 2;
		const halfFovX = Math.atan( Math.tan( halfFov ) * camera.aspect );
		const distance = FRAME_MARGIN * radius / Math.sin( Math.min( halfFov, halfFovX ) );

		camera.near = NEAR * radius;
		camera.far = FAR * radius;
		camera.position.set( center.x, center.y, center.z + distance );
		camera.up.set( 0, 1, 0 );
		camera.lookAt( center );
		camera.updateProjectionMatrix();

		this.controls.target.copy( center );
		this.controls.minDistance = MIN_DISTANCE * radius;
		this.controls.maxDistance = MAX_DISTANCE * radius;
		this.controls.update();
		this.invalidate();

	}

	/**
	 * Draw triangle edges instead of surfaces, for the current object and later ones.
	 * @param {boolean} on
	 */
	setWireframe( on ) {

		this.wireframe = Boolean( on );
		this.object?.traverse( ( child ) => {

			const materials = Array.isArray( child.material ) ? child.material : [ child.material ];
			for ( const material of materials ) {

				if ( material !== undefined && 'wireframe' in material ) material.wireframe = this.wireframe;

			}

		} );
		this.invalidate();

	}

	/**
	 * Where a world point appears on the page.
	 * @param {number[]} point - [x, y, z], world units.
	 * @returns {{x: number, y: number}} page CSS pixels, as MouseEvent.clientX / clientY.
	 */
	project( [ x, y, z ] ) {

		this._resize( false ); // the layout may have changed since the ResizeObserver last ran
		this.camera.updateMatrixWorld();
		const ndc = new Vector3( x, y, z ).project( this.camera );
		const rect = this.renderer.domElement.getBoundingClientRect();
		return {
			x: rect.left + ( ndc.x + 1 ) / 2 * rect.width,
			y: rect.top + ( 1 - ndc.y ) / 2 * rect.height,
		};

	}

	/** Draw a frame at the next animation frame (once, however often it is asked). */
	invalidate() {

		this._frameRequest ??= requestAnimationFrame( () => this._frame() );

	}

	/** Render now. */
	render() {

		this._resize( false );
		this.renderer.render( this.scene, this.camera );

	}

	/** Cancel the pending frame and free the renderer, the controls and the resize observer. */
	dispose() {

		if ( this._frameRequest !== null ) cancelAnimationFrame( this._frameRequest );
		this._frameRequest = null;
		this._resizeObserver.disconnect();
		this.controls.dispose();
		this.renderer.dispose();
		this.renderer.domElement.remove();

	}

	_frame() {

		this._frameRequest = null;
		// damping glides the camera on after the pointer lets go; while it moves, the
		// controls' 'change' asks for the next frame
		this.controls.update();
		this.render();

	}

	/**
	 * Match the drawing buffer and the camera to the container; if it changed, render now
	 * (`render`) or at the next frame.
	 */
	_resize( render = true ) {

		const width = Math.max( 1, this.container.clientWidth );
		const height = Math.max( 1, this.container.clientHeight );
		if ( width === this._width && height === this._height ) return;
		this._width = width;
		this._height = height;
		this.renderer.setSize( width, height, false );
		this.camera.aspect = width / height;
		this.camera.updateProjectionMatrix();
		if ( render ) this.render();
		else this.invalidate();

	}

}

/**
 * Tell the viewer whose scene holds `object` that it looks different, so its next frame
 * is drawn: scene objects call this after each visible change (an object outside any
 * viewer's scene is drawn when it is added).
 * @param {import('three').Object3D} object
 */
export function redraw( object ) {

	let root = object;
	while ( root.parent !== null ) root = root.parent;
	root.dispatchEvent( CHANGE );

}

const CHANGE = { type: 'change' };
