"""The base of every HTML form in the app.

Flask-WTF also fills forms from a JSON body, where a number or a nested
value breaks the fields (a 500). Our forms are HTML forms: they read the
form data only, so a JSON body leaves them empty (a 400 naming the missing
fields).
"""

from flask import request
from flask_wtf import FlaskForm
from flask_wtf.form import _Auto
from werkzeug.datastructures import CombinedMultiDict, ImmutableMultiDict


class Form(FlaskForm):
    class Meta(FlaskForm.Meta):
        def wrap_formdata(self, form, formdata):
            if formdata is not _Auto:  # given explicitly by the caller
                return formdata
            if request.method not in ("POST", "PUT", "PATCH", "DELETE"):
                return None
            if request.files:
                return CombinedMultiDict((request.files, request.form))
            return request.form or ImmutableMultiDict()
