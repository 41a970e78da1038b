"""ParaView view of a ddsolve result, written by ddsolve beside its viewer files.

    pvpython THIS_FILE --png picture.png   # headless (add xvfb-run -a where there is no display)
    paraview --script=THIS_FILE            # interactive

The layers side by side, displacements magnified by SCALE (the largest displacement drawn as a
fixed fraction of the domain), cells coloured by von Mises stress up to its PERCENTILE-th percentile
(the corner singularities would otherwise set the range), and the opening [u].nu of the crack faces
with the contact pressure along Sigma.  A 3-D box (SOLID): its two halves (or the regions of several
interfaces) warped by SCALE in one view, coloured by the displacement's magnitude, and beside it Sigma (each
Sigma, one above the other, the lowest at the bottom) seen from above, coloured by the opening.
"""
import argparse
import os
import sys

from paraview.simple import (AssignViewToLayout, ColorBy, CreateLayout, CreateView, GetColorTransferFunction,
                             GetScalarBar, OpenDataFile, Render, SaveScreenshot, Show, Text, WarpByVector)

@SETTINGS@

if "__file__" in globals():  # pvpython
    HERE = os.path.dirname(os.path.abspath(__file__))
else:  # ParaView's GUI runs scripts without __file__: where the files were written, else the working folder
    HERE = WRITTEN_TO if os.path.isfile(os.path.join(WRITTEN_TO, FILES["layer1"])) else os.getcwd()
DARK = [0.1, 0.1, 0.1]
IMAGE = [1600, 1000]  # pixels of the --png picture
LAYERS_HEIGHT = 0.62  # the layers' share of the height; the chart below
SIGMAS = [part for part in FILES if part.startswith("sigma")]  # Sigma, or sigma1, sigma2, ... bottom to top
LAYERS = ([part for part in FILES if part not in SIGMAS] if SOLID else  # a 3-D box's halves or regions
          [layer for layer in TITLES if layer in FILES])  # one or two
#: A layer's view in that picture, and the band of its height (fractions) between the colour bar
#: and the title, where the camera puts the layer.
VIEW_PIXELS = [IMAGE[0] / (1 if STACKED else len(LAYERS)), IMAGE[1] * LAYERS_HEIGHT / (len(LAYERS) if STACKED else 1)]
BAND = (110.0 / VIEW_PIXELS[1], 1.0 - 50.0 / VIEW_PIXELS[1])


def optional(proxy, **values):
    """Set the properties this ParaView version has (names change between versions)."""
    for key, value in values.items():
        try:
            setattr(proxy, key, value)
        except AttributeError:
            pass


def layer_view(layer):
    reader = OpenDataFile(os.path.join(HERE, FILES[layer]))
    warped = WarpByVector(Input=reader, Vectors=["POINTS", "displacement"], ScaleFactor=SCALE)
    view = CreateView("RenderView")
    view.OrientationAxesVisibility = 0
    optional(view, UseColorPaletteForBackground=0)
    view.Background = [1.0, 1.0, 1.0]
    display = Show(warped, view)
    display.Ambient, display.Diffuse = 1.0, 0.0  # flat colours: no lighting on a plane
    ColorBy(display, ("CELLS", "von_mises"), separate=True)
    lut = GetColorTransferFunction("von_mises", display, separate=True)
    lut.ApplyPreset("Viridis (matplotlib)", True)
    lut.AutomaticRescaleRangeMode = "Never"
    lut.RescaleTransferFunction(0.0, CEILINGS[layer])
    display.SetScalarBarVisibility(view, True)
    bar = GetScalarBar(lut, view)
    bar.Title = "von Mises stress (unit of E), top: %gth percentile" % PERCENTILE
    bar.ComponentTitle = ""
    bar.Orientation = "Horizontal"
    bar.WindowLocation = "Lower Center"
    bar.TitleColor = bar.LabelColor = DARK
    optional(bar, TitleFontSize=22, LabelFontSize=20, ScalarBarLength=0.6, ScalarBarThickness=24,
             RangeLabelFormat="%-#6.2g")
    label = Show(Text(Text="%s, displacements x%g" % (TITLES[layer], SCALE)), view)
    label.WindowLocation = "Upper Center"
    label.FontSize = 26
    label.Color = DARK
    view.InteractionMode = "2D"
    view.ResetCamera()
    x0, x1, y0, y1, _, _ = warped.GetDataInformation().GetBounds()
    low, high = BAND
    scale = max((y1 - y0) / (2.0 * (high - low)), (x1 - x0) / (2.0 * 0.94 * VIEW_PIXELS[0] / VIEW_PIXELS[1]))
    centre = [0.5 * (x0 + x1), 0.5 * (y0 + y1) - (low + high - 1.0) * scale, 0.0]
    view.CameraFocalPoint, view.CameraPosition = centre, centre[:2] + [10.0 * scale]
    view.CameraViewUp = [0.0, 1.0, 0.0]
    view.CameraParallelScale = scale
    return view


def coloured(display, view, array, low, high, title):
    """``display`` coloured by the point array ``array`` (a vector's magnitude) from ``low`` to ``high``, with a
    bar."""
    ColorBy(display, ("POINTS", array, "Magnitude") if array == "displacement" else ("POINTS", array), separate=True)
    lut = GetColorTransferFunction(array, display, separate=True)
    lut.ApplyPreset("Viridis (matplotlib)", True)
    lut.AutomaticRescaleRangeMode = "Never"
    lut.RescaleTransferFunction(low, high)
    display.SetScalarBarVisibility(view, True)
    bar = GetScalarBar(lut, view)
    bar.Title, bar.ComponentTitle = title, ""
    bar.Orientation = "Horizontal"
    bar.WindowLocation = "Lower Center"
    bar.TitleColor = bar.LabelColor = DARK
    optional(bar, TitleFontSize=22, LabelFontSize=20, ScalarBarLength=0.6, ScalarBarThickness=24,
             RangeLabelFormat="%-#6.2g")


def render_view(text):
    """A white render view titled ``text``."""
    view = CreateView("RenderView")
    view.OrientationAxesVisibility = 1
    optional(view, UseColorPaletteForBackground=0)
    view.Background = [1.0, 1.0, 1.0]
    label = Show(Text(Text=text), view)
    label.WindowLocation = "Upper Center"
    label.FontSize = 26
    label.Color = DARK
    return view


def solid_view():
    """The 3-D box's halves warped by SCALE, coloured by |u|, seen from the front, right and above."""
    view = render_view("%s: displacements x%g" % (TITLE, SCALE))
    for layer in LAYERS:
        warped = WarpByVector(Input=OpenDataFile(os.path.join(HERE, FILES[layer])),
                              Vectors=["POINTS", "displacement"], ScaleFactor=SCALE)
        coloured(Show(warped, view), view, "displacement", 0.0, CEILINGS[layer], "displacement magnitude")
    view.CameraPosition, view.CameraViewUp = [1.0, 0.8, 1.6], [0.0, 1.0, 0.0]
    view.CameraFocalPoint = [0.0, 0.0, 0.0]
    view.ResetCamera()
    return view


def sigma_map(part):
    """Sigma (the ``part`` of several) seen from above (along -y), coloured by the opening [u].nu."""
    view = render_view("Sigma: opening [u].nu" if part == "sigma" else "%s: opening [u].nu" % part)
    display = Show(OpenDataFile(os.path.join(HERE, FILES[part])), view)
    display.Ambient, display.Diffuse = 1.0, 0.0
    coloured(display, view, "normal_opening", OPENING[0], OPENING[1], "opening [u].nu (length unit)")
    view.InteractionMode = "2D"
    view.CameraPosition, view.CameraFocalPoint, view.CameraViewUp = [0.0, 1.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, -1.0]
    view.ResetCamera()
    return view


def sigma_view():
    reader = OpenDataFile(os.path.join(HERE, FILES["sigma"]))
    view = CreateView("XYChartView")
    view.ChartTitle = TITLE
    view.BottomAxisTitle = SIGMA_X_LABEL
    view.LeftAxisTitle = "opening (length unit)"
    view.RightAxisTitle = "contact pressure (unit of E)"
    optional(view, ChartTitleFontSize=26, LeftAxisTitleFontSize=22, BottomAxisTitleFontSize=22,
             RightAxisTitleFontSize=22, LegendFontSize=20, LeftAxisLabelFontSize=18, BottomAxisLabelFontSize=18,
             RightAxisLabelFontSize=18, ChartTitleBold=0, LeftAxisTitleBold=0, BottomAxisTitleBold=0,
             RightAxisTitleBold=0)
    line = Show(reader, view)
    line.AttributeType = "Point Data"
    line.UseIndexForXAxis = 0
    line.XArrayName = SIGMA_X
    line.SeriesVisibility = ["opening", "contact_pressure"]
    line.SeriesPlotCorner = ["contact_pressure", "1"]
    line.SeriesColor = ["opening", "0.12", "0.47", "0.71", "contact_pressure", "0.84", "0.15", "0.16"]
    line.SeriesLabel = ["opening", "opening (u+ - u-).nu, left axis", "contact_pressure",
                        "contact pressure, right axis"]
    return view


def main(argv):
    parser = argparse.ArgumentParser(description="Show a ddsolve result in ParaView.")
    parser.add_argument("--png", help="save the picture to this PNG file")
    options, _ = parser.parse_known_args(argv)
    layout = CreateLayout(TITLE)
    if SOLID:
        body = layout.SplitHorizontal(0, 0.55)
        AssignViewToLayout(solid_view(), layout, hint=body)
        cell = body + 1  # the right half: the Sigmas, the highest at the top
        for index, part in enumerate(reversed(SIGMAS)):
            if index < len(SIGMAS) - 1:  # this Sigma on top of the cell, the ones below it in the rest
                top = layout.SplitVertical(cell, 1.0 / (len(SIGMAS) - index))
                AssignViewToLayout(sigma_map(part), layout, hint=top)
                cell = top + 1
            else:
                AssignViewToLayout(sigma_map(part), layout, hint=cell)
        save(layout, options.png)
        return
    layers = layout.SplitVertical(0, LAYERS_HEIGHT)
    split = layout.SplitVertical if STACKED else layout.SplitHorizontal
    first = split(layers, 0.5) if len(LAYERS) > 1 else layers
    for position, layer in enumerate(LAYERS):
        AssignViewToLayout(layer_view(layer), layout, hint=first + position)
    AssignViewToLayout(sigma_view(), layout, hint=layers + 1)
    save(layout, options.png)


def save(layout, png):
    """Render the layout, and save it to ``png`` if given."""
    if png:
        layout.SetSize(*IMAGE)  # the picture's size (else the views are drawn small and magnified)
    Render()
    if png:
        SaveScreenshot(png, layout, ImageResolution=IMAGE)
        print("wrote " + png)


main(getattr(sys, "argv", [""])[1:])  # ParaView's GUI may run scripts without sys.argv
