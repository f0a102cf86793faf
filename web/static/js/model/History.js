/**
 * Undo and redo of edits, each kept as a step the editor knows how to take back and to
 * make again (landmarks keep the states before and after, painting the rows before and
 * after a stroke). A new step drops what could be redone.
 *
 * @template Step
 */
export class History {

	constructor() {

		/** @type {Step[]} */
		this._undo = [];
		/** @type {Step[]} */
		this._redo = [];

	}

	/** Whether there is a step to undo. */
	get canUndo() {

		return this._undo.length > 0;

	}

	/** Whether there is an undone step to redo. */
	get canRedo() {

		return this._redo.length > 0;

	}

	/**
	 * Remember a step just made; nothing is left to redo.
	 * @param {Step} step
	 */
	push( step ) {

		this._undo.push( step );
		this._redo.length = 0;

	}

	/**
	 * The step to take back (it moves to the redo list).
	 * @returns {Step|null} null when there is none.
	 */
	undo() {

		const step = this._undo.pop();
		if ( step === undefined ) return null;
		this._redo.push( step );
		return step;

	}

	/**
	 * The undone step to make again (it moves back to the undo list).
	 * @returns {Step|null} null when there is none.
	 */
	redo() {

		const step = this._redo.pop();
		if ( step === undefined ) return null;
		this._undo.push( step );
		return step;

	}

	/** Forget every step. */
	clear() {

		this._undo.length = 0;
		this._redo.length = 0;

	}

}
