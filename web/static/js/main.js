/**
 * Boot and wiring of the page: builds the viewer, the shared models, the picking tool and
 * the panels, hands them to the App (the project's life), and connects what one part does
 * to what others show: landmark edits to their panel, the draft and the hint; the
 * conditioning settings and the region mask to the project's saved settings and the
 * stream; the keyboard to the tool in use.
 *
 *   model/   LandmarkSet, ConditioningSettings, RegionMask, PaintedRig, ... (no DOM)
 *   net/     api (REST, jobs), StreamClient, wire (every binary format), saving queues
 *   scene/   Viewer, SkinnedFace and what the view draws (markers, brush cursor)
 *   tools/   pointer tools on the face: LandmarkPicker, WeightPainter
 *   panels/  one view per part of index.html
 */
import { App } from './App.js';
import { ConditioningSettings } from './model/ConditioningSettings.js';
import { LandmarkSet } from './model/LandmarkSet.js';
import { RegionMask } from './model/RegionMask.js';
import { ProjectSettings } from './net/ProjectSettings.js';
import { $ } from './panels/dom.js';
import { BlendshapesPanel } from './panels/BlendshapesPanel.js';
import { CustomLayoutPanel } from './panels/CustomLayoutPanel.js';
import { ErrorBanner } from './panels/ErrorBanner.js';
import { ExportPanel } from './panels/ExportPanel.js';
import { LandmarksPanel } from './panels/LandmarksPanel.js';
import { LivePanel } from './panels/LivePanel.js';
import { MeshUpload } from './panels/MeshUpload.js';
import { MouthPanel } from './panels/MouthPanel.js';
import { MusclesPanel } from './panels/MusclesPanel.js';
import { PaintPanel } from './panels/PaintPanel.js';
import { PerformancePanel } from './panels/PerformancePanel.js';
import { ProjectBar } from './panels/ProjectBar.js';
import { RigPanel } from './panels/RigPanel.js';
import { StereoLivePanel } from './panels/StereoLivePanel.js';
import { Viewer } from './scene/Viewer.js';
import { LandmarkPicker } from './tools/LandmarkPicker.js';

const viewer = new Viewer( $( 'viewport' ) );
const errors = new ErrorBanner( $( 'error' ) );
const landmarks = new LandmarkSet();
const app = new App( {
	viewer,
	errors,
	landmarks,
	picker: new LandmarkPicker( viewer, landmarks ),
	conditioning: new ConditioningSettings(),
	regions: new RegionMask(),
	projectSettings: new ProjectSettings( {
		onSaved: ( project ) => {

			// only the settings: a rig or landmarks stored meanwhile may be newer than this answer
			if ( app.project && app.project.id === project.id ) app.project = { ...app.project, settings: project.settings };

		},
		onError: ( error ) => errors.show( error ),
	} ),
} );
app.setPanels( {
	bar: new ProjectBar( app ),
	upload: new MeshUpload( app ),
	marks: new LandmarksPanel( app ),
	customLayout: new CustomLayoutPanel( app ),
	rig: new RigPanel( app ),
	mouth: new MouthPanel( app ),
	paint: new PaintPanel( app ),
	muscles: new MusclesPanel( app ),
	blendshapes: new BlendshapesPanel( app ),
	sources: new PerformancePanel( app ),
	stereo: new StereoLivePanel( app ),
	live: new LivePanel( app ),
	exports: new ExportPanel( app ),
} );

landmarks.addEventListener( 'change', () => {

	app.showLandmarks();
	app.marks.scheduleDraft();

} );
app.picker.addEventListener( 'hover', ( event ) => app.updateHint( event.detail.index ) );
app.paint.painter.addEventListener( 'change', () => app.updateHint() );
app.conditioning.addEventListener( 'change', () => {

	if ( app.projectId ) app.projectSettings.schedule( app.projectId, 'conditioning', () => app.conditioning.toJSON() );
	app.sources.sendSettings();

} );
app.regions.addEventListener( 'change', () => {

	if ( app.projectId ) app.projectSettings.schedule( app.projectId, 'held_regions', () => app.regions.toJSON() );
	app.live.sendMask();

} );

$( 'wireframe' ).addEventListener( 'change', ( event ) => viewer.setWireframe( event.target.checked ) );
for ( const id of [ 'surface-texture', 'surface-shaded' ] ) $( id ).addEventListener( 'change', () => app.showSurface() );
$( 'frame-view' ).addEventListener( 'click', () => viewer.frame() );
window.addEventListener( 'keydown', async ( event ) => {

	try {

		await key( event );

	} catch ( error ) {

		errors.show( error );

	}

} );
window.addEventListener( 'beforeunload', () => {

	if ( app.projectSettings.pending ) app.projectSettings.flush( { keepalive: true } );
	if ( app.blendshapes.pending ) app.blendshapes.flush( { keepalive: true } );
	if ( app.blendshapes.painter.saveState === 'unsaved' ) app.blendshapes.painter.flush( { keepalive: true } );

} );

/** A key goes to the dialog, the text field, the painter or the landmarks, else to the view. */
async function key( event ) {

	const target = event.target;
	if ( target.closest?.( 'dialog[open]' ) ) return;
	const typing = target instanceof HTMLInputElement && target.type !== 'checkbox' && target.type !== 'radio' || target instanceof HTMLSelectElement || target instanceof HTMLTextAreaElement;
	const k = event.key.toLowerCase();
	if ( k === 'escape' ) {

		if ( errors.visible ) errors.clear();
		else landmarks.select( - 1 );
		return;

	}

	if ( typing ) return;
	if ( app.paint.key( event ) || app.blendshapes.painter.key( event ) ) {

		event.preventDefault();
		return;

	}

	if ( await app.marks.key( event ) || event.ctrlKey || event.metaKey || event.altKey ) return;
	if ( k === 'w' ) $( 'wireframe' ).click();
	else if ( k === 't' && ! $( 'surface-switch' ).hidden ) $( $( 'surface-texture' ).checked ? 'surface-shaded' : 'surface-texture' ).click();
	else if ( k === 'f' ) viewer.frame();

}

window.app = app;
app.start();
