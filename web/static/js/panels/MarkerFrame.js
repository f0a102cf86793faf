/**
 * The first frame of a tracked marker video with each marker labelled (m01, ...) where the
 * server found it (GET .../takes/{take}/preview and /preview/markers): a click on a label
 * picks that marker. Labels sit at percentages of the image, so they stay on their markers
 * at any panel width. Markers not seen on the first frame have no label.
 */
export class MarkerFrame {

	/**
	 * @param {(name: string) => void} onPick - a marker's label was clicked.
	 */
	constructor( onPick ) {

		this.root = document.createElement( 'div' );
		this.root.id = 'custom-frame';
		this.root.style.position = 'relative';
		this.root.style.lineHeight = '0';
		this.root.hidden = true;
		this.image = document.createElement( 'img' );
		this.image.id = 'custom-frame-image';
		this.image.alt = 'the video\'s first frame';
		this.image.style.width = '100%';
		this.root.append( this.image );
		/** @type {Map<string, HTMLButtonElement>} */
		this.labels = new Map();
		this.root.addEventListener( 'click', ( event ) => {

			const name = event.target.closest?.( 'button' )?.dataset.marker;
			if ( name ) onPick( name );

		} );

	}

	/**
	 * Show a frame and its markers; null hides the view.
	 * @param {{url: string, size: number[], markers: Array<{name: string, x: number|null, y: number|null}>}|null} frame
	 */
	show( frame ) {

		for ( const label of this.labels.values() ) label.remove();
		this.labels.clear();
		this.root.hidden = ! frame;
		if ( ! frame ) {

			this.image.removeAttribute( 'src' );
			return;

		}

		this.image.src = frame.url;
		const [ width, height ] = frame.size;
		for ( const { name, x, y } of frame.markers ) {

			if ( x === null || y === null ) continue;
			const label = document.createElement( 'button' );
			label.type = 'button';
			label.dataset.marker = name;
			label.textContent = name;
			label.title = `${ name }: click, then click its point on the mesh`;
			// the label's corner at the marker, a dot marking the spot exactly
			Object.assign( label.style, {
				position: 'absolute', left: `${ 100 * x / width }%`, top: `${ 100 * y / height }%`,
				transform: 'translate(-3px, -3px)', padding: '0 3px 0 8px', margin: '0', minWidth: '0',
				height: '14px', font: '10px/14px sans-serif', color: '#fff', border: 'none', borderRadius: '3px',
				background: 'radial-gradient(circle at 3px 3px, #ff3 2.5px, rgba(0,0,0,0.55) 3px)',
				cursor: 'pointer',
			} );
			this.labels.set( name, label );
			this.root.append( label );

		}

	}

	/**
	 * Mark which marker is chosen and which are placed on the mesh.
	 * @param {string|null} chosen
	 * @param {Set<string>} placed
	 */
	mark( chosen, placed ) {

		for ( const [ name, label ] of this.labels ) {

			label.style.outline = name === chosen ? '2px solid #4af' : '';
			label.style.color = placed.has( name ) ? '#8f8' : '#fff';
			label.setAttribute( 'aria-pressed', String( name === chosen ) );

		}

	}

}
