//! The built-in Cornell box: the published Cornell University geometry (millimetres), used when no scene
//! file is given.
