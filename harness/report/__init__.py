"""Tables, figures and the HTML index, rebuilt from stored results; never imports the runner."""
